"""Candidate landmarks of a shared class: rays of detections no mapped landmark explains.

A hypothesis starts from one detection at each keyframe of a straight movement whose rays meet
ahead of both (the impartial PDF's two vision cones overlap); every pairing the cones allow is
kept. Later keyframes add a ray when a detection falls in the hypothesis's gate and count a miss
when none does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from pipeline.association.predict import ray_point_cov
from pipeline.joint.geometry import intersect_rays


@dataclass(frozen=True)
class Ray:
    """One detection of a class, placed: keyframe ``(movement, end)``, origin and direction (FL)."""

    movement: int
    end: int
    detection: int
    bearing_rad: float
    origin_fl: tuple[float, float]
    direction_rad: float


@dataclass
class Hypothesis:
    """A possible landmark of class ``label``: its rays, point, covariance and misses (FL)."""

    label: str
    rays: list[Ray]
    point_fl: NDArray[np.float64]
    cov_fl: NDArray[np.float64]
    rms_rad: float
    misses: int = 0
    born: int = 0
    keys: set[tuple[int, int, int]] = field(default_factory=set)

    @property
    def movements(self) -> set[int]:
        """Movements whose keyframes saw it."""
        return {r.movement for r in self.rays}


#: Every ray of a hypothesis must pass this close to its point (in eps) ...
FIT_TOL_EPS = 1.0
#: ... and they must span at least this parallax (in eps; the paper's bound for a usable cone
#: intersection is 2 eps).
MIN_PARALLAX_EPS = 2.0


def fit(label: str, rays: list[Ray], eps_rad: float, sigma_rad: float) -> Hypothesis | None:
    """The hypothesis through ``rays``, or None when they do not all meet ahead within
    :data:`FIT_TOL_EPS` with a parallax of at least :data:`MIN_PARALLAX_EPS`."""
    origins = np.array([r.origin_fl for r in rays], np.float64)
    dirs = np.array([r.direction_rad for r in rays], np.float64)
    tol = FIT_TOL_EPS * eps_rad
    found = intersect_rays(origins, dirs, tol)
    if found is None or found.parallax_rad < MIN_PARALLAX_EPS * eps_rad:
        return None
    d = found.point_fl - origins
    ang = np.arctan2(d[:, 1], d[:, 0])
    err = np.abs(np.angle(np.exp(1j * (ang - dirs))))
    if np.any(err > tol):  # every ray must agree: no outlier dropped here
        return None
    cov = ray_point_cov(found.point_fl, origins, sigma_rad)
    keys = {(r.movement, r.end, r.detection) for r in rays}
    return Hypothesis(
        label,
        list(rays),
        found.point_fl,
        cov,
        float(math.sqrt(float(np.mean(err**2)))),
        born=min(r.movement for r in rays),
        keys=keys,
    )
