"""A synthetic driving robot with a 360-degree bearing sensor (for tests and experiments).

The robot drives at constant speed towards waypoints drawn in its arena's driving area,
steering with a bounded turn rate, so its path is smooth and turns while it drives. Its wheel
odometry integrates the true increments with slip: a scale error per run
(``scale_std``) and per step (``slip_std``, relative) on the distance, and heading noise per
radian turned and per metre driven. Every ``bearing_period_s`` the sensor measures the bearing
of every landmark within ``range_m`` that no nearer landmark (a disc of ``radius_m``) hides,
with Gaussian noise, each missed with probability ``dropout``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad


@dataclass(frozen=True)
class Arena:
    """Landmarks and where the robot drives (world frame, m).

    Attributes
    ----------
    name : str
    landmarks_world : dict name -> (2,) float
    reference : (str, str)
        The reference pair L1, L2.
    area : (x_min, y_min, x_max, y_max)
        Where waypoints are drawn.
    """

    name: str
    landmarks_world: dict[str, NDArray[np.float64]]
    reference: tuple[str, str]
    area: tuple[float, float, float, float]


def _ring(names: str, points: list[tuple[float, float]]) -> dict[str, NDArray[np.float64]]:
    return {f"{names}{i + 1}": np.array(p, np.float64) for i, p in enumerate(points)}


def arenas() -> dict[str, Arena]:
    """The simulated arenas: ``square`` (8 landmarks round a 6 x 6 m room), ``long`` (a 24 x 4 m
    corridor, 12 landmarks along its walls), ``few`` (3 landmarks), ``far`` (driving in 2 x 2 m,
    landmarks 7-11 m away: narrow parallax)."""
    square = [(0, 0), (3, -0.5), (6, 0), (6.5, 3), (6, 6), (3, 6.5), (0, 6), (-0.5, 3)]
    long = [(x, y) for x in (0.0, 6.0, 12.0, 18.0, 24.0, 30.0) for y in (-0.5, 4.5)]
    few = [(0.0, 0.0), (5.0, 0.5), (2.0, 5.0)]
    far = [(0.0, 0.0), (9.0, -7.0), (11.0, 2.0), (4.0, 9.0), (-7.0, 6.0)]
    return {
        "square": Arena("square", _ring("L", square), ("L1", "L2"), (1.0, 1.0, 5.0, 5.0)),
        "long": Arena("long", _ring("L", long), ("L1", "L3"), (1.0, 1.0, 29.0, 3.0)),
        "few": Arena("few", _ring("L", few), ("L1", "L2"), (1.0, 1.0, 4.0, 3.5)),
        "far": Arena("far", _ring("L", far), ("L1", "L2"), (0.0, 0.5, 2.0, 2.5)),
    }


@dataclass(frozen=True)
class DrivingSpec:
    """How the simulated robot drives and senses (SI units)."""

    duration_s: float = 120.0
    dt_s: float = 0.05
    speed_m_s: float = 0.25
    turn_rate_max_rad_s: float = 0.8
    bearing_period_s: float = 0.2
    bearing_std_rad: float = math.radians(0.5)
    range_m: float = 12.0
    radius_m: float = 0.08
    dropout: float = 0.05
    scale_std: float = 0.02
    slip_std: float = 0.05
    rot_std_per_rad: float = 0.03
    rot_std_per_m: float = 0.01
    start_world: tuple[float, float, float] | None = None


@dataclass
class DrivingRun:
    """A simulated drive.

    Attributes
    ----------
    t_ns : (n,) int
        Odometry sample times.
    truth_world : (n, 3) float
        True poses (m, m, rad).
    odometry : (n, 3) float
        Integrated wheel odometry (odometry frame: starts at (0, 0, 0)).
    bearing_sets : list of (t_ns, dict name -> bearing_rad)
        The sensor's measurements.
    arena : Arena
    """

    t_ns: NDArray[np.int64]
    truth_world: NDArray[np.float64]
    odometry: NDArray[np.float64]
    bearing_sets: list[tuple[int, dict[str, float]]] = field(default_factory=list)
    arena: Arena | None = None


def _waypoint(
    area: tuple[float, float, float, float], rng: np.random.Generator
) -> NDArray[np.float64]:
    x0, y0, x1, y1 = area
    return np.array([rng.uniform(x0, x1), rng.uniform(y0, y1)])


def sense(
    pose: NDArray[np.float64],
    landmarks_world: dict[str, NDArray[np.float64]],
    spec: DrivingSpec,
    rng: np.random.Generator,
) -> dict[str, float]:
    """One bearing set from true pose (3,): visible landmarks' noisy bearings (rad)."""
    names = list(landmarks_world)
    pts = np.array([landmarks_world[n] for n in names])
    d = pts - pose[:2]
    r = np.hypot(d[:, 0], d[:, 1])
    ang = np.arctan2(d[:, 1], d[:, 0])
    half = np.arcsin(np.clip(spec.radius_m / np.maximum(r, spec.radius_m), 0.0, 1.0))
    out = {}
    for j, name in enumerate(names):
        if r[j] > spec.range_m or rng.random() < spec.dropout:
            continue
        nearer = r < r[j]
        if np.any(nearer & (np.abs(wrap_rad(ang - ang[j])) < half)):
            continue
        b = ang[j] - pose[2] + rng.normal(0.0, spec.bearing_std_rad)
        out[name] = float(wrap_rad(float(b)))
    return out


def simulate_drive(arena: Arena, spec: DrivingSpec, rng: np.random.Generator) -> DrivingRun:
    """Drive ``spec.duration_s`` in ``arena`` (see the module doc)."""
    n = round(spec.duration_s / spec.dt_s) + 1
    x0, y0, x1, y1 = arena.area
    start = spec.start_world or (0.5 * (x0 + x1), 0.5 * (y0 + y1), rng.uniform(-math.pi, math.pi))
    pose = np.array(start, np.float64)
    odom = np.zeros(3)
    scale = 1.0 + rng.normal(0.0, spec.scale_std)
    truth = np.empty((n, 3))
    odometry = np.empty((n, 3))
    t_ns = np.round(np.arange(n) * spec.dt_s * 1e9).astype(np.int64)
    goal = _waypoint(arena.area, rng)
    sets: list[tuple[int, dict[str, float]]] = []
    every = max(1, round(spec.bearing_period_s / spec.dt_s))
    for i in range(n):
        truth[i], odometry[i] = pose, odom
        if i % every == 0:
            sets.append((int(t_ns[i]), sense(pose, arena.landmarks_world, spec, rng)))
        if np.hypot(*(goal - pose[:2])) < 0.5:
            goal = _waypoint(arena.area, rng)
        want = float(wrap_rad(math.atan2(goal[1] - pose[1], goal[0] - pose[0]) - pose[2]))
        w = float(np.clip(2.0 * want, -spec.turn_rate_max_rad_s, spec.turn_rate_max_rad_s))
        ds, dth = spec.speed_m_s * spec.dt_s, w * spec.dt_s
        # exact arc from the pose: heading at mid-step
        mid = pose[2] + 0.5 * dth
        pose = np.array([pose[0] + ds * math.cos(mid), pose[1] + ds * math.sin(mid), pose[2] + dth])
        pose[2] = float(wrap_rad(float(pose[2])))
        ds_o = ds * (scale + rng.normal(0.0, spec.slip_std))
        rot_std = spec.rot_std_per_rad * abs(dth) + spec.rot_std_per_m * ds
        dth_o = dth + rng.normal(0.0, rot_std)
        mid_o = odom[2] + 0.5 * dth_o
        odom = np.array(
            [odom[0] + ds_o * math.cos(mid_o), odom[1] + ds_o * math.sin(mid_o), odom[2] + dth_o]
        )
        odom[2] = float(wrap_rad(float(odom[2])))
    return DrivingRun(t_ns, truth, odometry, sets, arena)
