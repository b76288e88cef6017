"""The simulated world: a rectangular arena with coloured (or band-coded) cylindrical landmarks.

World frame: metres, origin at an arena corner, x along the arena width, y along its height.
A robot pose is ``(x, y, heading)`` in the world frame (heading in rad, CCW from world +x).
Bearings are relative to the robot heading, CCW positive, wrapped to [-pi, pi).

Public API
----------
- :class:`Arena`, :class:`Landmark`: plain descriptions (also used by the scenario file).
- :class:`SimWorld`: the arena plus its landmarks as arrays, with the geometry the renderer and
  the planner need: :meth:`SimWorld.bearings_rad`, :meth:`SimWorld.ranges_m`,
  :meth:`SimWorld.half_widths_rad`, :meth:`SimWorld.occluded_fractions`,
  :meth:`SimWorld.move_problem`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad
from data_schemas.colors import class_label

#: A robot pose in the world frame: x (m), y (m), heading (rad).
Pose = tuple[float, float, float]


@dataclass(frozen=True)
class Arena:
    """Rectangular arena ``[0, width_m] x [0, height_m]`` (world frame, m)."""

    width_m: float
    height_m: float

    def contains(self, x: float, y: float, margin_m: float = 0.0) -> bool:
        """True if ``(x, y)`` is inside the arena shrunk by ``margin_m`` on every side."""
        return (
            margin_m <= x <= self.width_m - margin_m and margin_m <= y <= self.height_m - margin_m
        )


@dataclass(frozen=True)
class Landmark:
    """A vertical coloured cylinder standing on the floor.

    Attributes
    ----------
    name : str
        Catalog name (e.g. ``"L1"``).
    x, y : float
        Centre, world frame, m.
    color : str or None
        Colour of a single-colour landmark (a key of ``data_schemas.colors.NOMINAL_BGR``);
        None for a coded landmark.
    radius_m, height_m : float
        Cylinder size, m.
    bands : tuple of str
        A coded landmark's band colours, top to bottom, equal heights (empty: single colour).
    """

    name: str
    x: float
    y: float
    color: str | None
    radius_m: float = 0.01
    height_m: float = 0.15
    bands: tuple[str, ...] = ()

    @property
    def label(self) -> str:
        """The landmark's class: its colour or its band code (``"magenta-yellow"``)."""
        return class_label(self.color, self.bands)

    @property
    def paint(self) -> tuple[str, ...]:
        """The colours painted from top to bottom: the bands, or the one colour."""
        return self.bands if self.bands else (str(self.color),)


@dataclass(frozen=True, eq=False)
class SimWorld:
    """An arena and its landmarks, with vectorised geometry over the landmarks.

    Attributes
    ----------
    arena : Arena
    landmarks : tuple of Landmark
    xy_world : ndarray, shape (N, 2)
        Landmark centres, m (derived).
    radius_m : ndarray, shape (N,)
        Landmark radii, m (derived).
    """

    arena: Arena
    landmarks: tuple[Landmark, ...]
    xy_world: NDArray[np.float64] = field(init=False, repr=False)
    radius_m: NDArray[np.float64] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        xy = np.array([[lm.x, lm.y] for lm in self.landmarks], np.float64).reshape(-1, 2)
        radius = np.array([lm.radius_m for lm in self.landmarks], np.float64)
        object.__setattr__(self, "xy_world", xy)
        object.__setattr__(self, "radius_m", radius)

    @property
    def names(self) -> tuple[str, ...]:
        """Landmark names in catalog order."""
        return tuple(lm.name for lm in self.landmarks)

    def bearings_rad(self, pose_world: Pose) -> NDArray[np.float64]:
        """True bearing of each landmark centre from ``pose_world``, shape (N,), [-pi, pi)."""
        x, y, heading = pose_world
        d = self.xy_world - (x, y)
        return wrap_rad(np.arctan2(d[:, 1], d[:, 0]) - heading)

    def ranges_m(self, pose_world: Pose) -> NDArray[np.float64]:
        """Distance from the robot to each landmark centre, shape (N,), m."""
        x, y, _ = pose_world
        d = self.xy_world - (x, y)
        return np.hypot(d[:, 0], d[:, 1])

    def half_widths_rad(self, pose_world: Pose) -> NDArray[np.float64]:
        """Angular half-width of each cylinder seen from ``pose_world``, shape (N,), rad.

        ``asin(radius / range)``; pi/2 if the robot is inside the cylinder.
        """
        ratio = self.radius_m / np.maximum(self.ranges_m(pose_world), 1e-12)
        return np.arcsin(np.minimum(ratio, 1.0))

    def occluded_fractions(self, pose_world: Pose) -> NDArray[np.float64]:
        """Fraction of each landmark's angular extent hidden by nearer landmarks, shape (N,).

        0 = fully visible, 1 = fully hidden; exact on the angular intervals
        ``[bearing - half_width, bearing + half_width]``.
        """
        bearing = self.bearings_rad(pose_world)
        half = self.half_widths_rad(pose_world)
        dist = self.ranges_m(pose_world)
        rel = wrap_rad(bearing[None, :] - bearing[:, None])  # rel[i, j]: bearing of j seen from i
        covers = (np.abs(rel) < half[:, None] + half[None, :]) & (dist[None, :] < dist[:, None])
        out = np.zeros(len(self.landmarks))
        for i in np.flatnonzero(covers.any(axis=1) & (half > 0)):
            j = covers[i]
            lo = np.maximum(rel[i, j] - half[j], -half[i])
            hi = np.minimum(rel[i, j] + half[j], half[i])
            hidden, reach = 0.0, -math.inf
            for a, z in sorted(zip(lo.tolist(), hi.tolist(), strict=True)):
                a = max(a, reach)
                if z > a:
                    hidden += z - a
                    reach = z
            out[i] = min(hidden / (2.0 * half[i]), 1.0)
        return out

    def move_problem(
        self,
        pose_world: Pose,
        turn_rad: float,
        distance_m: float,
        *,
        robot_radius_m: float,
        clearance_m: float,
    ) -> str | None:
        """Why a move (turn in place, then drive straight) is unsafe, or None if it is fine.

        Parameters
        ----------
        pose_world : (x, y, heading)
            Pose before the move (world frame, m, rad).
        turn_rad, distance_m : float
            The move.
        robot_radius_m : float
            Radius of the robot's footprint.
        clearance_m : float
            Gap kept between the robot's edge and the walls (at the end point) and every
            cylinder's surface (along the path; if the robot starts closer, the path must not
            bring it closer than it was). It absorbs actuation noise.

        Returns
        -------
        str or None
            A short reason, e.g. ``"would end at (1.100, 0.300) m, less than 0.070 m from a
            wall of the 1.05 x 0.68 m arena"``.
        """
        x0, y0, heading = pose_world
        h = heading + turn_rad
        x1, y1 = x0 + distance_m * math.cos(h), y0 + distance_m * math.sin(h)
        margin = robot_radius_m + clearance_m
        if not self.arena.contains(x1, y1, margin):
            return (
                f"would end at ({x1:.3f}, {y1:.3f}) m, less than {margin:.3f} m from a wall "
                f"of the {self.arena.width_m:g} x {self.arena.height_m:g} m arena"
            )
        if not self.landmarks:
            return None
        p0 = np.array([x0, y0])
        seg = np.array([x1 - x0, y1 - y0])
        rel = self.xy_world - p0
        t = np.clip(rel @ seg / max(float(seg @ seg), 1e-18), 0.0, 1.0)
        closest = np.hypot(*(rel - t[:, None] * seg).T)
        start = np.hypot(rel[:, 0], rel[:, 1])
        required = np.minimum(self.radius_m + margin, start)
        bad = np.flatnonzero(closest < required - 1e-12)
        if bad.size:
            lm = self.landmarks[int(bad[0])]
            return (
                f"would pass {closest[bad[0]]:.3f} m from landmark {lm.name} at "
                f"({lm.x:g}, {lm.y:g}); it needs {float(required[bad[0]]):.3f} m"
            )
        return None
