"""Candidate landmarks of a shared class: rays of detections no mapped landmark explains.

A hypothesis starts from one detection at each keyframe of a straight movement whose rays meet
ahead of both (the impartial PDF's two vision cones overlap); every pairing the cones allow is
kept. Later keyframes add a ray when a detection falls in the hypothesis's gate and count a miss
when none does. :func:`crossings` and :class:`RaySet` serve the search among unnamed
detections; :func:`ray_fits` tells whether a ray is a bearing of a mapped landmark.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad
from pipeline.association.predict import GATE_CHI2, ray_point_cov
from pipeline.estimate import LandmarkEstimate
from pipeline.geometry import intersect_rays, solve_sym_2x2


@dataclass(frozen=True)
class Ray:
    """One detection of a class, placed: keyframe ``(movement, end)``, origin and direction (FL)."""

    movement: int
    end: int
    detection: int
    bearing_rad: float
    origin_fl: tuple[float, float]
    direction_rad: float

    @classmethod
    def placed(
        cls,
        movement: int,
        end: int,
        detection: int,
        bearing_rad: float,
        origin_fl: NDArray[np.float64],
        heading_rad: float,
    ) -> Ray:
        """Detection ``detection`` (bearing, rad) of keyframe ``(movement, end)`` seen from
        ``origin_fl`` (2,) with heading ``heading_rad`` (FL)."""
        origin = (float(origin_fl[0]), float(origin_fl[1]))
        return cls(movement, end, detection, bearing_rad, origin, heading_rad + bearing_rad)


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
    _lines: dict[tuple[float, int], int] = field(default_factory=dict, repr=False, compare=False)

    def lines_of_sight(self, min_rad: float) -> int:
        """Distinct lines of sight: keyframes whose lines through the point (modulo pi: a
        keyframe behind the point lies on the same line) differ by more than ``min_rad``.
        Keyframes on one line of sight test nothing: any point of the line fits them all.
        Kept per ``min_rad`` and number of rays (a named landmark's rays grow in place)."""
        key = (min_rad, len(self.rays))
        if (known := self._lines.get(key)) is None:
            d = np.array([r.origin_fl for r in self.rays]) - self.point_fl
            ang = np.mod(np.arctan2(d[:, 1], d[:, 0]), math.pi)
            kept: list[float] = []
            for a in ang:
                if all(abs(math.sin(a - k)) > math.sin(min_rad) for k in kept):
                    kept.append(float(a))
            known = self._lines[key] = len(kept)
        return known

    @property
    def movements(self) -> set[int]:
        """Movements whose keyframes saw it."""
        return {r.movement for r in self.rays}


#: Every ray of a hypothesis must pass this close to its point (in eps) ...
FIT_TOL_EPS = 1.0
#: ... and they must span at least this parallax (in eps; the paper's bound for a usable cone
#: intersection is 2 eps).
MIN_PARALLAX_EPS = 2.0


def cannot_meet(r1: Ray, r2: Ray, eps_rad: float) -> bool:
    """True when :func:`fit` is sure to refuse the pair ``(r1, r2)``: their lines cross behind
    one of them, or ahead of both with less than :data:`MIN_PARALLAX_EPS` of parallax.

    Scalars, about a microsecond: most pairings of one class's detections at O1 and O2 are
    refused, and this spares them the fit. Near the limits (nearly parallel rays, a crossing at
    an origin, a parallax within 1e-6 rad of the bound) it says False and leaves them to fit.
    """
    c1, s1 = math.cos(r1.direction_rad), math.sin(r1.direction_rad)
    c2, s2 = math.cos(r2.direction_rad), math.sin(r2.direction_rad)
    cross = c1 * s2 - s1 * c2
    if abs(cross) < 1e-3:
        return False
    dx = r2.origin_fl[0] - r1.origin_fl[0]
    dy = r2.origin_fl[1] - r1.origin_fl[1]
    t1 = (dx * s2 - dy * c2) / cross  # the crossing is origin + t * direction on each ray
    t2 = (dx * s1 - dy * c1) / cross
    if min(abs(t1), abs(t2)) < 1e-3:
        return False
    if t1 < 0.0 or t2 < 0.0:
        return True  # behind a ray: its bearing is off by pi
    parallax = abs(math.remainder(r1.direction_rad - r2.direction_rad, math.tau))
    return parallax < MIN_PARALLAX_EPS * eps_rad - 1e-6


def fit(
    label: str,
    rays: list[Ray],
    eps_rad: float,
    sigma_rad: float,
    guess_fl: NDArray[np.float64] | None = None,
) -> Hypothesis | None:
    """The hypothesis through ``rays``, or None when they do not all meet ahead within
    :data:`FIT_TOL_EPS` with a parallax of at least :data:`MIN_PARALLAX_EPS`.

    With ``guess_fl`` (the point of the hypothesis the rays grew from) the point is the
    least-squares point of all rays, each weighted by ``1 / range^2`` from the guess (twice),
    instead of the robust search of :func:`pipeline.geometry.intersect_rays`; two rays
    meet where they cross.
    """
    origins = np.array([r.origin_fl for r in rays], np.float64)
    dirs = np.array([r.direction_rad for r in rays], np.float64)
    tol = FIT_TOL_EPS * eps_rad
    if guess_fl is None and len(rays) == 2:  # two rays: their crossing, whatever the weights
        guess_fl = origins.mean(axis=0)
    point = _least_squares(origins, dirs, guess_fl) if guess_fl is not None else None
    if point is None:
        found = intersect_rays(origins, dirs, tol)
        if found is None:
            return None
        point = found.point_fl
    d = point - origins
    ang = np.arctan2(d[:, 1], d[:, 0])
    err = np.abs(wrap_rad(ang - dirs))
    if float(err.max()) > tol:  # every ray must agree: no outlier dropped here
        return None
    if float(np.abs(wrap_rad(ang[:, None] - ang[None, :])).max()) < MIN_PARALLAX_EPS * eps_rad:
        return None
    cov = ray_point_cov(point, origins, sigma_rad)
    keys = {(r.movement, r.end, r.detection) for r in rays}
    return Hypothesis(
        label,
        list(rays),
        point,
        cov,
        float(math.sqrt(float(np.mean(err**2)))),
        born=min(r.movement for r in rays),
        keys=keys,
    )


def _least_squares(
    origins_fl: NDArray[np.float64], dirs_rad: NDArray[np.float64], guess_fl: NDArray[np.float64]
) -> NDArray[np.float64] | None:
    """Point (2,) nearest the rays in angle: perpendicular distances weighted by
    ``1 / range^2`` from the current point, twice from ``guess_fl``; None if degenerate."""
    nx, ny = -np.sin(dirs_rad), np.cos(dirs_rad)
    rhs = nx * origins_fl[:, 0] + ny * origins_fl[:, 1]
    px, py = float(guess_fl[0]), float(guess_fl[1])
    for _ in range(2):
        w = 1.0 / np.maximum((px - origins_fl[:, 0]) ** 2 + (py - origins_fl[:, 1]) ** 2, 1e-9)
        wx, wy = w * nx, w * ny
        x, y, bad = solve_sym_2x2(wx @ nx, wx @ ny, wy @ ny, wx @ rhs, wy @ rhs)
        if bad:
            return None
        px, py = float(x), float(y)
    return np.array([px, py])


class RaySet:
    """Rays sorted by keyframe, as arrays (origins (r, 2), directions (r,), keyframe ids (r,))."""

    def __init__(self, rays: Sequence[Ray]) -> None:
        frames = np.array([2 * r.movement + r.end for r in rays], np.int64)
        order = np.argsort(frames, kind="stable")
        self.rays = [rays[int(i)] for i in order]
        self.frames = frames[order]
        self.origins_fl = np.array([r.origin_fl for r in self.rays], np.float64).reshape(-1, 2)
        self.dirs_rad = np.array([r.direction_rad for r in self.rays], np.float64)
        self.units = np.column_stack((np.cos(self.dirs_rad), np.sin(self.dirs_rad)))
        self.starts = np.flatnonzero(np.r_[True, self.frames[1:] != self.frames[:-1]])

    def errors(self, points_fl: NDArray[np.float64]) -> NDArray[np.float64]:
        """Angle (c, r) between each ray and the direction from its origin to each point (c, 2);
        inf for a point behind the ray."""
        d = points_fl[:, None, :] - self.origins_fl[None, :, :]
        err = np.abs(wrap_rad(np.arctan2(d[..., 1], d[..., 0]) - self.dirs_rad[None, :]))
        ahead = (d * self.units[None, :, :]).sum(axis=2) > 0.0
        out: NDArray[np.float64] = np.where(ahead, err, np.inf)
        return out

    def keyframes_within(self, err: NDArray[np.float64], tol_rad: float) -> NDArray[np.int64]:
        """Per point (row of ``err`` (c, r)), the keyframes with a ray within ``tol_rad``."""
        near = (err <= tol_rad).astype(np.int8)
        out: NDArray[np.int64] = np.maximum.reduceat(near, self.starts, axis=1).sum(axis=1)
        return out

    def nearest_per_keyframe(self, err: NDArray[np.float64], tol_rad: float) -> list[Ray]:
        """For one point (``err`` (r,)), each keyframe's ray nearest it, if within ``tol_rad``."""
        out = []
        for lo, hi in zip(self.starts, [*self.starts[1:], err.size], strict=True):
            k = lo + int(np.argmin(err[lo:hi]))
            if err[k] <= tol_rad:
                out.append(self.rays[k])
        return out


def crossings(rs: RaySet, index: int, min_parallax_rad: float) -> NDArray[np.float64]:
    """Where each ray at O1 of movement ``index`` crosses each ray at its O2, ahead of both
    with at least ``min_parallax_rad`` between them: points (c, 2) FL."""
    a = np.flatnonzero(rs.frames == 2 * index)
    b = np.flatnonzero(rs.frames == 2 * index + 1)
    ua, ub = rs.units[a][:, None, :], rs.units[b][None, :, :]
    cross = ua[..., 0] * ub[..., 1] - ua[..., 1] * ub[..., 0]
    d = rs.origins_fl[b][None, :, :] - rs.origins_fl[a][:, None, :]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # parallel: no crossing
        t1 = (d[..., 0] * ub[..., 1] - d[..., 1] * ub[..., 0]) / cross
        t2 = (d[..., 0] * ua[..., 1] - d[..., 1] * ua[..., 0]) / cross
    parallax = np.abs(wrap_rad(rs.dirs_rad[a][:, None] - rs.dirs_rad[b][None, :]))
    ia, ib = np.nonzero((t1 > 0.0) & (t2 > 0.0) & (parallax >= min_parallax_rad))
    out: NDArray[np.float64] = rs.origins_fl[a][ia] + t1[ia, ib][:, None] * rs.units[a][ia]
    return out


def ray_fits(r: Ray, e: LandmarkEstimate, sigma_rad: float) -> bool:
    """Whether ray ``r`` is within the gate of the bearing of ``e`` predicted from its
    keyframe (bearing noise std ``sigma_rad`` for the ray and for the bearings that placed
    ``e``; first order, as :func:`~pipeline.association.predict.predict_bearings`, in
    scalars: a few rays and landmarks at a time)."""
    dx, dy = float(e.mean_fl[0]) - r.origin_fl[0], float(e.mean_fl[1]) - r.origin_fl[1]
    r2 = max(dx * dx + dy * dy, 1e-12)
    jx, jy = -dy / r2, dx / r2
    c = e.cov_fl
    var = jx * jx * c[0, 0] + 2 * jx * jy * c[0, 1] + jy * jy * c[1, 1] + 2 * sigma_rad**2
    err = math.remainder(math.atan2(dy, dx) - r.direction_rad, math.tau)
    return err * err <= GATE_CHI2 * float(var)
