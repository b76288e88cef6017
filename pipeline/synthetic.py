"""Simulated bearings from known geometry (no images): for tests, benchmarks and examples.

The default geometry is the paper's arena (:mod:`data_schemas.paper_arena`): 1.05 x 0.68 m, four
landmarks, reference pair (L1, L2).
The robot drives a polygonal path of straight movements in random directions, 0.10-0.25 m
long, staying inside the arena and away from the landmarks. Bearing noise: Gaussian of std
``sigma_frac * eps`` truncated to ``[-eps, eps]`` (the bound the method assumes).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad
from data_schemas.errors import EstimationError
from data_schemas.paper_arena import PAPER_ARENA_M, PAPER_LANDMARKS_M, PAPER_REFERENCE
from pipeline.frame_change import to_fl
from pipeline.priors import ImpartialPrior
from pipeline.slam import MovementObservation


@dataclass(frozen=True)
class SimulatedRun:
    """Bearings of a simulated run and the truth they came from (world frame, m, rad).

    Attributes
    ----------
    observations : list of MovementObservation
    o1_world, o2_world : ndarray (m, 2)
        Start and end of each movement.
    heading_world : ndarray (m,)
    landmarks_world : dict of name -> ndarray (2,)
    """

    observations: list[MovementObservation]
    o1_world: NDArray[np.float64]
    o2_world: NDArray[np.float64]
    heading_world: NDArray[np.float64]
    landmarks_world: dict[str, NDArray[np.float64]]

    def truth_fl(
        self, reference: tuple[str, str] = PAPER_REFERENCE
    ) -> dict[str, NDArray[np.float64]]:
        """True landmark positions in FL (reference pair at (0,0) and (1,0))."""
        l1 = self.landmarks_world[reference[0]]
        l2 = self.landmarks_world[reference[1]]
        return {k: to_fl(v, l1, l2) for k, v in self.landmarks_world.items()}


def _seg_dist(p: NDArray[np.float64], a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    ab = b - a
    t = min(1.0, max(0.0, float((p - a) @ ab) / float(ab @ ab)))
    return float(np.sqrt(((a + t * ab - p) ** 2).sum()))


def simulate_bearings(
    n_movements: int,
    rng: np.random.Generator,
    *,
    eps_rad: float = math.radians(3.0),
    sigma_frac: float = 0.5,
    landmarks_world: Mapping[str, tuple[float, float]] = PAPER_LANDMARKS_M,
    arena_m: tuple[float, float] = PAPER_ARENA_M,
    move_m: tuple[float, float] = (0.10, 0.25),
    clearance_m: float = 0.06,
) -> SimulatedRun:
    """Draw a random polygonal path and the noisy bearings of every landmark at each stop."""
    lms = {k: np.asarray(v, dtype=np.float64) for k, v in landmarks_world.items()}
    pos_l = np.array(list(lms.values()))
    lo = np.array([clearance_m, clearance_m])
    hi = np.array(arena_m) - clearance_m

    def free(p: NDArray[np.float64]) -> bool:
        inside = bool(np.all(p >= lo) and np.all(p <= hi))
        return inside and float(np.sqrt(((pos_l - p) ** 2).sum(axis=1)).min()) >= clearance_m

    start = rng.uniform(lo, hi)
    while not free(start):
        start = rng.uniform(lo, hi)
    noise = ImpartialPrior(eps_rad, sigma_frac=sigma_frac)
    obs: list[MovementObservation] = []
    o1s, o2s, heads = [], [], []
    for t in range(n_movements):
        for _ in range(10_000):
            h = rng.uniform(-math.pi, math.pi)
            length = rng.uniform(*move_m)
            end = start + length * np.array([math.cos(h), math.sin(h)])
            if free(end) and all(_seg_dist(p, start, end) >= clearance_m for p in pos_l):
                break
        else:
            raise EstimationError("could not draw a movement that stays in the arena")
        b = []
        for o in (start, end):
            d = pos_l - o
            true = np.arctan2(d[:, 1], d[:, 0]) - h
            b.append(wrap_rad(true + noise.sample_angle(len(lms), rng)))
        obs.append(
            MovementObservation(
                t,
                {k: float(v) for k, v in zip(lms, b[0], strict=True)},
                {k: float(v) for k, v in zip(lms, b[1], strict=True)},
            )
        )
        o1s.append(start)
        o2s.append(end)
        heads.append(h)
        start = end
    return SimulatedRun(obs, np.array(o1s), np.array(o2s), np.array(heads), lms)


def scatter_landmarks(
    rng: np.random.Generator,
    placed: Mapping[str, tuple[float, float]],
    n_landmarks: int,
    lo_m: tuple[float, float],
    hi_m: tuple[float, float],
    spacing_m: float,
) -> dict[str, tuple[float, float]]:
    """``placed`` plus landmarks ``L<k>`` drawn uniformly in the box ``lo_m``-``hi_m`` (world, m),
    each more than ``spacing_m`` from the others, up to ``n_landmarks`` in all."""
    pts = dict(placed)
    while len(pts) < n_landmarks:
        p = rng.uniform(lo_m, hi_m)
        if all(math.dist(p, q) > spacing_m for q in pts.values()):
            pts[f"L{len(pts) + 1}"] = (float(p[0]), float(p[1]))
    return pts


@dataclass(frozen=True)
class Arena:
    """A randomly drawn arena for stress tests (world frame, m, deg).

    Attributes
    ----------
    size_m : (width, height)
    landmarks_world : dict of name -> (x, y)
    reference : (str, str)
        Any two of the landmarks (not necessarily close to each other or to the robot).
    bearing_noise_deg : float
        Std of the bearing noise (Gaussian, truncated at eps).
    move_m : (min, max)
        Length range of the straight movements (scaled with the arena).
    """

    size_m: tuple[float, float]
    landmarks_world: dict[str, tuple[float, float]]
    reference: tuple[str, str]
    bearing_noise_deg: float
    move_m: tuple[float, float]


def random_arena(
    rng: np.random.Generator,
    *,
    max_size_m: tuple[float, float] = (3.0, 2.0),
    extra_landmarks: tuple[int, int] = (2, 6),
    noise_deg: tuple[float, float] = (0.0, 1.5),
    spacing_m: float = 0.15,
) -> Arena:
    """Draw an arena: size up to ``max_size_m``, ``2 + extra`` landmarks at least ``spacing_m``
    apart, a random reference pair, a bearing noise std in ``noise_deg``."""
    w = float(rng.uniform(0.8, max_size_m[0]))
    h = float(rng.uniform(0.6, min(max_size_m[1], w)))
    n = 2 + int(rng.integers(extra_landmarks[0], extra_landmarks[1] + 1))
    pts: dict[str, tuple[float, float]] = {}
    while len(pts) < n:
        p = rng.uniform([0.05, 0.05], [w - 0.05, h - 0.05])
        if all(math.dist(p, q) > spacing_m for q in pts.values()):
            pts[f"L{len(pts) + 1}"] = (float(p[0]), float(p[1]))
    a, b = (int(i) for i in rng.choice(n, 2, replace=False))
    scale = max(w, h) / PAPER_ARENA_M[0]
    return Arena(
        (w, h),
        pts,
        (f"L{a + 1}", f"L{b + 1}"),
        float(rng.uniform(*noise_deg)),
        (0.10 * scale, 0.25 * scale),
    )
