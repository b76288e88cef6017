"""Bearing geometry without GTSAM: poses, predicted bearings, resection, ray intersection.

Placement and triangulation that the joint estimator (:mod:`pipeline.joint`), association
(:mod:`pipeline.association`) and batch least squares (:mod:`pipeline.batch_ls`) share.
Everything is in FL (unit |L1 L2|) except :func:`triangulate_fr` (a movement's frame FR:
O1 = (0, 0), O2 = (1, 0)). A movement's keyframes are ``O1`` (start) and
``O2 = O1 + d (cos h, sin h)`` (end), both with heading ``h``; a bearing is the angle of a
landmark seen from a keyframe, relative to ``h`` (rad, CCW).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad

#: Candidate start points per axis of the resection's grid search.
GRID_STEPS = 9
#: Candidate movement lengths (FL) of the resection's search.
LENGTHS_FL = np.geomspace(0.02, 4.0, 48)


@dataclass(frozen=True)
class KeyframePose:
    """One keyframe as the map has it.

    Attributes
    ----------
    origin_fl : (2,) float
        Position, FL.
    heading_rad : float
        Heading (FL, CCW from the x axis); bearings are measured from it.
    cov : (3, 3) float
        Covariance of ``(x, y, heading)`` perturbations in the keyframe's own frame (x ahead,
        y to the left; FL^2, FL rad, rad^2).
    """

    origin_fl: NDArray[np.float64]
    heading_rad: float
    cov: NDArray[np.float64]


@dataclass(frozen=True)
class MovementPose:
    """Start point, heading and length of one straight movement (FL).

    Attributes
    ----------
    o1_fl : (2,) float
        Start keyframe position.
    heading_rad : float
        Heading during the movement (FL, CCW from the x axis).
    length_fl : float
        Distance O1 -> O2 (> 0).
    """

    o1_fl: NDArray[np.float64]
    heading_rad: float
    length_fl: float

    @classmethod
    def from_ends(
        cls, o1_fl: NDArray[np.float64], heading_rad: float, o2_fl: NDArray[np.float64]
    ) -> MovementPose:
        """The movement from keyframe O1 (2,) with its heading to keyframe O2 (2,): its length
        is their distance (at least 1e-9 FL), its heading O1's."""
        return cls(o1_fl, heading_rad, max(float(np.hypot(*(o2_fl - o1_fl))), 1e-9))

    @property
    def o2_fl(self) -> NDArray[np.float64]:
        """End keyframe position (2,)."""
        u = np.array([math.cos(self.heading_rad), math.sin(self.heading_rad)])
        out: NDArray[np.float64] = self.o1_fl + self.length_fl * u
        return out


def predicted_bearings(
    origins_fl: NDArray[np.float64],
    headings_rad: NDArray[np.float64],
    points_fl: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Bearings (k,) of points (k, 2) seen from origins (k, 2) with headings (k,), in [-pi, pi)."""
    dx = points_fl[:, 0] - origins_fl[:, 0]  # by column: arctan2 on strided rows is 2x slower
    dy = points_fl[:, 1] - origins_fl[:, 1]
    return wrap_rad(np.arctan2(dy, dx) - headings_rad)


def bearing_point(
    origins: NDArray[np.float64],
    directions_rad: NDArray[np.float64],
    start: NDArray[np.float64],
    weights: NDArray[np.float64] | None = None,
    *,
    steps: int = 5,
    tol: float = 1e-12,
    min_det: float = 0.0,
) -> NDArray[np.float64]:
    """The point (2,) that minimises the (weighted) squared bearing errors of rays, by
    Gauss-Newton from ``start`` (the point so far is kept when a step cannot be taken).

    Parameters
    ----------
    origins : (n, 2) float
        Where each ray starts (any frame; the point comes out in it).
    directions_rad : (n,) float
        Each ray's direction in that frame, rad.
    start : (2,) float
        The first point.
    weights : (n,) float, optional
        Each ray's weight (inverse variance); equal when None.
    steps, tol : int, float
        At most ``steps`` steps, stopping once a step's squared length is below ``tol``.
    min_det : float
        The normal matrix must have a determinant above this for a step.
    """
    w = np.ones(len(directions_rad)) if weights is None else np.asarray(weights, np.float64)
    p = np.asarray(start, np.float64).copy()
    for _ in range(steps):
        d = p - origins
        r2 = np.maximum((d**2).sum(axis=1), 1e-12)
        jac = np.column_stack((-d[:, 1], d[:, 0])) / r2[:, None]  # d bearing / d point
        res = wrap_rad(directions_rad - np.arctan2(d[:, 1], d[:, 0]))
        lhs = jac.T @ (w[:, None] * jac)
        if min_det > 0.0 and abs(float(np.linalg.det(lhs))) < min_det:
            return p
        try:
            step = np.linalg.solve(lhs, jac.T @ (w * res))
        except np.linalg.LinAlgError:
            return p
        if not np.all(np.isfinite(step)):
            return p
        p = p + step
        if float(step @ step) < tol:
            break
    return p


#: Minimal parallax (rad) for a two-view triangulation (:func:`triangulate_fr`) to count.
MIN_PARALLAX_RAD = math.radians(1.0)


def triangulate_fr(b1_rad: float, b2_rad: float) -> NDArray[np.float64] | None:
    """Intersection (2,) FR of the rays from (0,0) and (1,0), or None if they do not meet ahead."""
    s = math.sin(b2_rad - b1_rad)
    if abs(s) < math.sin(MIN_PARALLAX_RAD):
        return None
    r1 = math.sin(b2_rad) / s
    r2 = math.sin(b1_rad) / s
    if r1 <= 0.0 or r2 <= 0.0:
        return None
    return np.array([r1 * math.cos(b1_rad), r1 * math.sin(b1_rad)])


@dataclass(frozen=True)
class Sightings:
    """Bearings of known points from one movement's two keyframes.

    Attributes
    ----------
    points_fl : (k, 2) float
        The known landmark positions.
    end : (k,) int
        0 for a bearing taken at O1, 1 for one taken at O2.
    bearings_rad : (k,) float
        The measured bearings.
    """

    points_fl: NDArray[np.float64]
    end: NDArray[np.int64]
    bearings_rad: NDArray[np.float64]

    def residuals(self, params: NDArray[np.float64]) -> NDArray[np.float64]:
        """Wrapped bearing errors (..., k) for movement parameters (..., 4) = x, y, h, log d."""
        x, y, h, logd = (params[..., i, None] for i in range(4))
        d = _length(logd) * self.end
        ox = x + d * np.cos(h)
        oy = y + d * np.sin(h)
        pred = np.arctan2(self.points_fl[:, 1] - oy, self.points_fl[:, 0] - ox) - h
        out: NDArray[np.float64] = wrap_rad(self.bearings_rad - pred)
        return out

    def subset(self, keep: NDArray[np.bool_]) -> Sightings:
        """The sightings selected by a mask (k,)."""
        return Sightings(self.points_fl[keep], self.end[keep], self.bearings_rad[keep])


#: Bounds on a movement's log length in the solver (FL units): e^30 is far beyond any arena, and
#: an unbounded Levenberg-Marquardt step must not overflow ``exp``.
LOG_LENGTH_BOUND = 30.0


def _length(log_length: NDArray[np.float64] | float) -> NDArray[np.float64]:
    """A movement's length from its log length, bounded to +-:data:`LOG_LENGTH_BOUND`."""
    out: NDArray[np.float64] = np.exp(np.clip(log_length, -LOG_LENGTH_BOUND, LOG_LENGTH_BOUND))
    return out


def _heading_from(s: Sightings, o1_fl: NDArray[np.float64]) -> NDArray[np.float64]:
    """Circular mean heading (n,) that fits the O1 bearings best from start points (n, 2)."""
    at = s.end == 0
    d = s.points_fl[at][None, :, :] - o1_fl[:, None, :]
    ang = np.arctan2(d[..., 1], d[..., 0]) - s.bearings_rad[at]
    out: NDArray[np.float64] = np.arctan2(np.sin(ang).sum(axis=1), np.cos(ang).sum(axis=1))
    return out


_Terms = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], float, float]


def _at(s: Sightings, x: NDArray[np.float64]) -> _Terms:
    """Offsets keyframe -> point (dx, dy: (k,)) at movement parameters ``x`` (4,), each
    sighting's distance from O1 along the movement (k,), and cos h, sin h."""
    h = float(x[2])
    length = math.exp(min(max(float(x[3]), -LOG_LENGTH_BOUND), LOG_LENGTH_BOUND))
    d: NDArray[np.float64] = length * s.end.astype(np.float64)
    c, sn = math.cos(h), math.sin(h)
    dx: NDArray[np.float64] = s.points_fl[:, 0] - (x[0] + d * c)
    dy: NDArray[np.float64] = s.points_fl[:, 1] - (x[1] + d * sn)
    return dx, dy, d, c, sn


def _wrapped_residuals(s: Sightings, terms: _Terms, x: NDArray[np.float64]) -> NDArray[np.float64]:
    """:meth:`Sightings.residuals` at parameters ``x`` (4,) from their :func:`_at` terms."""
    dx, dy, *_ = terms
    return wrap_rad(s.bearings_rad - (np.arctan2(dy, dx) - float(x[2])))


def _residuals_at(s: Sightings, x: NDArray[np.float64]) -> NDArray[np.float64]:
    """:meth:`Sightings.residuals` for one parameter vector ``x`` (4,) (scalar heading terms)."""
    return _wrapped_residuals(s, _at(s, x), x)


def _jacobian_of(terms: _Terms) -> NDArray[np.float64]:
    """d(predicted bearing)/d(x, y, h, log d) (k, 4) from the :func:`_at` terms."""
    dx, dy, d, c, sn = terms
    r2 = np.maximum(dx * dx + dy * dy, 1e-300)
    jac = np.empty((dx.size, 4))
    jac[:, 0] = da_dox = dy / r2  # d atan2(dy, dx) / d(observer x)
    jac[:, 1] = da_doy = -dx / r2
    jac[:, 2] = -1.0 + da_dox * (-d * sn) + da_doy * (d * c)
    jac[:, 3] = da_dox * (d * c) + da_doy * (d * sn)
    return jac


def _jacobian(s: Sightings, x: NDArray[np.float64]) -> NDArray[np.float64]:
    """d(predicted bearing)/d(x, y, h, log d) (k, 4) at parameters ``x`` (4,)."""
    return _jacobian_of(_at(s, x))


def _refine(
    s: Sightings, x0: NDArray[np.float64], iters: int = 30
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Levenberg-Marquardt on the 4 movement parameters: the fit (4,) and its residuals (k,)
    (:meth:`Sightings.residuals` there)."""
    x, lam = x0.copy(), 1e-3
    terms = _at(s, x)
    r = _wrapped_residuals(s, terms, x)
    cost = float(r @ r)
    normal: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None
    for _ in range(iters):
        if normal is None:  # the Jacobian changes only when a step is taken
            jac = _jacobian_of(terms)  # residual = measured - predicted: d residual = -jac
            normal = jac.T @ jac, jac.T @ r
        a = normal[0].copy()
        diag = a.flat[::5]  # the diagonal of the 4 x 4 (a copy)
        a.flat[::5] = diag + lam * (diag + 1e-12)
        try:
            delta = np.linalg.solve(a, normal[1])
        except np.linalg.LinAlgError:
            break
        cand = x + delta
        cand_terms = _at(s, cand)
        rc = _wrapped_residuals(s, cand_terms, cand)
        c = float(rc @ rc)
        if c < cost:
            x, r, terms, lam, normal = cand, rc, cand_terms, lam * 0.3, None
            done = cost - c < 1e-8 * cost
            cost = c
            if done:
                break
        else:
            lam *= 10.0
            if lam > 1e8:
                break
    return x, r


@dataclass(frozen=True)
class Resection:
    """A movement placed from bearings of known points.

    Attributes
    ----------
    pose : MovementPose
        The best fit.
    residuals_rad : (k,) float
        Bearing errors at the fit.
    inliers : (k,) bool
        The bearings the fit used (the others were beyond ``outlier_rad``).
    position_std_fl : float
        Std (FL) of O1 along its worst direction for a bearing noise of std 1 rad (scale by the
        noise; inf when the bearings do not determine the movement).
    log_length_std : float
        Std of ``log d`` for a bearing noise of std 1 rad.
    """

    pose: MovementPose
    residuals_rad: NDArray[np.float64]
    inliers: NDArray[np.bool_]
    position_std_fl: float
    log_length_std: float


def resect(
    s: Sightings,
    *,
    guesses: list[MovementPose],
    o1_known_fl: NDArray[np.float64] | None = None,
    outlier_rad: float | None = None,
) -> Resection | None:
    """Place a movement from bearings of known points (O1 free, or known when chained).

    Starts from ``guesses`` and from ``o1_known_fl`` (the previous movement's end: the robot
    turns in place) or, without it, from a grid of start points over the known points' box
    (1 FL margin); the best few of these
    (heading from the O1 bearings, length searched on :data:`LENGTHS_FL`) are refined by
    Levenberg-Marquardt. With ``outlier_rad``, the worst bearing beyond it is dropped and the fit
    redone, while more than four remain (wrong detections). None if there are no bearings at O1
    (the heading is then unknown).
    """
    if not np.any(s.end == 0) or s.points_fl.shape[0] == 0:
        return None
    if o1_known_fl is not None:
        o1 = np.asarray(o1_known_fl, np.float64).reshape(1, 2)
    else:
        lo = s.points_fl.min(axis=0) - 1.0
        hi = s.points_fl.max(axis=0) + 1.0
        gx, gy = np.meshgrid(
            np.linspace(lo[0], hi[0], GRID_STEPS), np.linspace(lo[1], hi[1], GRID_STEPS)
        )
        o1 = np.column_stack((gx.ravel(), gy.ravel()))
    h = _heading_from(s, o1)
    n, m = o1.shape[0], LENGTHS_FL.size
    cand = np.empty((n, m, 4))
    cand[..., 0] = o1[:, None, 0]
    cand[..., 1] = o1[:, None, 1]
    cand[..., 2] = h[:, None]
    cand[..., 3] = np.log(LENGTHS_FL)[None, :]
    cost = (s.residuals(cand.reshape(-1, 4)) ** 2).sum(axis=1)
    order = np.argsort(cost)[: 1 if o1_known_fl is not None else 4]
    seeds = [cand.reshape(-1, 4)[i] for i in order]
    seeds += [pose_params(g) for g in guesses]
    best: tuple[NDArray[np.float64], NDArray[np.float64], float] | None = None
    for x0 in seeds:
        x, r = _refine(s, x0)
        c = float(r @ r)
        if best is None or c < best[2]:
            best = (x, r, c)
    assert best is not None
    x, r, _ = best
    keep = np.ones(s.bearings_rad.size, bool)
    while outlier_rad is not None and keep.sum() > 4 and np.abs(r[keep]).max() > outlier_rad:
        keep[np.flatnonzero(keep)[np.argmax(np.abs(r[keep]))]] = False  # a wrong detection
        x, _ = _refine(s.subset(keep), x)
        r = _residuals_at(s, x)
    pos, logd = determinacy(s.subset(keep), x, o1_known=o1_known_fl is not None)
    pose = MovementPose(x[:2].copy(), float(wrap_rad(float(x[2]))), float(_length(x[3])))
    return Resection(pose, r, keep, pos, logd)


def place_chained(
    s: Sightings, o1_fl: NDArray[np.float64], sigma_rad: float
) -> tuple[MovementPose, float] | None:
    """A movement that starts exactly at ``o1_fl`` (2,) FL, where the last one ended (the robot
    turns in place), in closed form: heading from the bearings at O1 (circular mean), length
    from those at O2 (least squares on the rays' perpendicular distances along the heading,
    each weighted by 1 / range^2 from O1); with the std (FL) of that length for a bearing noise
    of std ``sigma_rad``. None when the bearings at O2 do not fix the length.

    Association places a chained movement with it (:mod:`pipeline.association.match`). The
    joint estimator's :func:`resect` with ``o1_known_fl`` starts there but fits O1 too."""
    at1, at2 = s.end == 0, s.end == 1
    d1 = s.points_fl[at1] - o1_fl
    ang = np.arctan2(d1[:, 1], d1[:, 0]) - s.bearings_rad[at1]
    heading = math.atan2(float(np.sin(ang).sum()), float(np.cos(ang).sum()))
    u = np.array([math.cos(heading), math.sin(heading)])
    p2 = s.points_fl[at2]
    dirs = heading + s.bearings_rad[at2]
    n = np.column_stack((-np.sin(dirs), np.cos(dirs)))
    w = 1.0 / np.maximum(((p2 - o1_fl) ** 2).sum(axis=1), 1e-9)
    nu = n @ u
    den = float((w * nu**2).sum())
    if den < 1e-6 * float(w.sum()):
        return None
    t = -float((w * nu * ((o1_fl - p2) * n).sum(axis=1)).sum()) / den
    if not t > 1e-3:
        return None
    pos_std = sigma_rad / math.sqrt(den)
    return MovementPose(np.asarray(o1_fl, np.float64), heading, t), pos_std


def pose_params(pose: MovementPose) -> NDArray[np.float64]:
    """A pose as the resection's parameters (4,): x, y (FL), heading (rad), log length."""
    return np.array([pose.o1_fl[0], pose.o1_fl[1], pose.heading_rad, math.log(pose.length_fl)])


def determinacy(
    s: Sightings, x: NDArray[np.float64], *, o1_known: bool = False
) -> tuple[float, float]:
    """How well bearings ``s`` pin a movement at parameters ``x`` (4,): std (FL) of O1 along
    its worst direction and std of ``log d``, for a bearing noise of std 1 rad (inf when they
    do not determine it). ``o1_known``: O1 is pinned (the turn in place after a placed
    movement)."""
    jac = _jacobian(s, x)
    free = slice(2, 4) if o1_known else slice(0, 4)  # the turn in place pins O1
    info = (jac.T @ jac)[free, free]
    try:
        cov = np.linalg.inv(info)
        pos = 0.0 if o1_known else widest_std(cov[:2, :2])
        logd = math.sqrt(max(float(cov[-1, -1]), 0.0))
    except np.linalg.LinAlgError:
        return math.inf, math.inf
    if not (math.isfinite(pos) and math.isfinite(logd)) or np.linalg.cond(info) > 1e14:
        return math.inf, math.inf
    return pos, logd


def keyframe_poses_of(
    s: Sightings, pose: MovementPose, sigma_rad: float
) -> tuple[KeyframePose, KeyframePose] | None:
    """O1 and O2 of a movement fit to bearings ``s`` (bearing noise std ``sigma_rad``), each
    with the covariance of its ``(x, y, heading)`` in its own frame; None when the bearings do
    not determine the movement."""
    x = pose_params(pose)
    jac = _jacobian(s, x)
    info = jac.T @ jac
    if not np.all(np.isfinite(info)) or np.linalg.cond(info) > 1e14:
        return None
    cov = np.linalg.inv(info) * sigma_rad**2
    c, sn, d = math.cos(pose.heading_rad), math.sin(pose.heading_rad), pose.length_fl
    to_o1 = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
    to_o2 = np.array([[1.0, 0.0, -d * sn, d * c], [0.0, 1.0, d * c, d * sn], [0.0, 0.0, 1.0, 0.0]])
    rot = np.array([[c, sn, 0.0], [-sn, c, 0.0], [0.0, 0.0, 1.0]])  # FL -> the keyframe's frame
    o1, o2 = (
        KeyframePose(origin, pose.heading_rad, rot @ j @ cov @ j.T @ rot.T)
        for origin, j in ((pose.o1_fl, to_o1), (pose.o2_fl, to_o2))
    )
    return o1, o2


@dataclass(frozen=True)
class RayFix:
    """A landmark placed by intersecting its rays.

    Attributes
    ----------
    point_fl : (2,) float
        The least-squares intersection.
    parallax_rad : float
        The widest angle between two of its rays, seen from the point.
    rms_rad : float
        RMS of the bearing errors at the point.
    """

    point_fl: NDArray[np.float64]
    parallax_rad: float
    rms_rad: float


def solve_sym_2x2(
    axx: NDArray[np.float64],
    axy: NDArray[np.float64],
    ayy: NDArray[np.float64],
    bx: NDArray[np.float64],
    by: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Solutions of symmetric 2x2 systems ``[[axx, axy], [axy, ayy]] p = b`` (any shape), and
    which are degenerate (``|det| < 1e-12 trace^2``; their solution is not to be used)."""
    det = axx * ayy - axy * axy
    bad = np.abs(det) < 1e-12 * (axx + ayy) ** 2
    safe = np.where(bad, 1.0, det)
    return (ayy * bx - axy * by) / safe, (axx * by - axy * bx) / safe, bad


def _intersect_many(
    ox: NDArray[np.float64],
    oy: NDArray[np.float64],
    nx: NDArray[np.float64],
    ny: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Least-squares points of groups of rays (origins ``ox, oy`` and unit normals ``nx, ny``,
    each (..., k): one group per leading index), squared perpendicular distances, then once
    more weighted by 1 / range^2 from the first point; x, y (...) and which are degenerate."""
    rhs = nx * ox + ny * oy
    w = np.ones_like(ox)
    px = py = np.zeros(ox.shape[:-1])
    bad = np.zeros(ox.shape[:-1], bool)
    for _ in range(2):
        wx, wy = w * nx, w * ny
        px, py, now = solve_sym_2x2(
            (wx * nx).sum(-1),
            (wx * ny).sum(-1),
            (wy * ny).sum(-1),
            (wx * rhs).sum(-1),
            (wy * rhs).sum(-1),
        )
        bad |= now
        w = 1.0 / np.maximum((px[..., None] - ox) ** 2 + (py[..., None] - oy) ** 2, 1e-9)
    return px, py, bad


def _intersect(
    origins_fl: NDArray[np.float64], u: NDArray[np.float64]
) -> NDArray[np.float64] | None:
    """Least-squares point of rays (origins (k, 2), unit directions (k, 2)), range-weighted."""
    px, py, bad = _intersect_many(origins_fl[:, 0], origins_fl[:, 1], -u[:, 1], u[:, 0])
    return None if bool(bad) else np.array([float(px), float(py)])


def _ray_errors(
    point_fl: NDArray[np.float64],
    origins_fl: NDArray[np.float64],
    directions_rad: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Angle (k,) between each ray and the direction to the point (pi: behind)."""
    points = np.broadcast_to(point_fl, origins_fl.shape)
    return np.abs(predicted_bearings(origins_fl, directions_rad, points))


def intersect_rays(
    origins_fl: NDArray[np.float64], directions_rad: NDArray[np.float64], inlier_rad: float
) -> RayFix | None:
    """Robust intersection of rays (k >= 2) from origins (k, 2) along directions (k,) (FL, rad).

    Every pair of rays proposes its crossing; the one that most rays pass within ``inlier_rad``
    of (ties: smallest squared error, then the first pair in index order) wins, and the
    least-squares point of those rays (squared perpendicular distances, then once more weighted
    by 1 / range^2, so that each ray counts by its angular error) is the fix. None if no two
    rays cross ahead of both.
    """
    k = origins_fl.shape[0]
    if k < 2:
        return None
    u = np.column_stack((np.cos(directions_rad), np.sin(directions_rad)))
    # every pair's crossing at once; the first of the best in (i, j) order wins, squared errors
    # equal to rounding counting as equal (two rays alone always cross exactly)
    i, j = np.triu_indices(k, 1)
    pair = np.stack((i, j), axis=1)
    px, py, bad = _intersect_many(origins_fl[pair, 0], origins_fl[pair, 1], -u[pair, 1], u[pair, 0])
    dx = px[:, None] - origins_fl[None, :, 0]
    dy = py[:, None] - origins_fl[None, :, 1]
    err = np.abs(wrap_rad(np.arctan2(dy, dx) - directions_rad[None, :]))  # (pairs, k)
    inl = err <= inlier_rad
    rows = np.arange(i.size)
    ok = ~bad & inl[rows, i] & inl[rows, j]
    if not ok.any():
        return None
    count = inl.sum(axis=1)
    top = ok & (count == count[ok].max())
    sq = np.where(top, np.where(inl, err**2, 0.0).sum(axis=1), np.inf)
    inl = inl[int(np.argmax(sq <= sq.min() + 1e-12 * inlier_rad**2))]
    p = _intersect(origins_fl[inl], u[inl])
    if p is None:
        return None
    err = _ray_errors(p, origins_fl[inl], directions_rad[inl])
    if np.any(err > inlier_rad):
        return None
    d = p - origins_fl[inl]
    ang = np.arctan2(d[:, 1], d[:, 0])
    spread = wrap_rad(ang[:, None] - ang[None, :])
    return RayFix(p, float(np.abs(spread).max()), float(np.sqrt(np.mean(err**2))))


def widest_std(cov: NDArray[np.floating[Any]]) -> float:
    """Standard deviation along the widest axis of a symmetric covariance (n, n): the square
    root of its largest eigenvalue (0 when rounding makes that negative); units of the
    covariance's square root."""
    return math.sqrt(max(float(np.linalg.eigvalsh(cov)[-1]), 0.0))
