"""Vision cones in FR and their intersection ``A_i`` (docs/method.md, part 3).

In FR the observation points are ``O1 = (0, 0)`` and ``O2 = (1, 0)``. A bearing ``b`` seen from
``O`` with error bound ``eps`` gives the cone ``{O + r (cos a, sin a) : |a - b| <= eps,
r_min <= r <= r_max}``. ``A_i`` is the intersection of the two cones. The two infinite wedges
(half-angle ``eps < 90 deg``, so each is convex) meet in a convex polygon, computed exactly by
half-plane clipping; the range annuli are applied by rejection when sampling.

Degenerate geometry is reported as :class:`Degenerate` with a one-line reason, never NaN/inf:

* parallax ``|wrap(b2 - b1)| <= 2 eps``: the wedges' direction intervals overlap, so ``A_i`` is
  unbounded (landmark near the line of motion, or too far for this baseline);
* the wedges do not meet (the bearings diverge);
* the intersection lies entirely nearer than ``r_min`` or farther than ``r_max``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad

O1_FR = np.array([0.0, 0.0])
O2_FR = np.array([1.0, 0.0])


@dataclass(frozen=True)
class Degenerate:
    """Why a landmark cannot be initialized in this movement (one line)."""

    reason: str


def vision_cone_polygon(
    origin: NDArray[np.float64],
    bearing_rad: float,
    eps_rad: float,
    r_min: float,
    r_max: float,
    k: int = 16,
) -> NDArray[np.float64]:
    """The vision cone as a closed-ring polygon for display: (2k, 2), near arc then far arc."""
    a = np.linspace(bearing_rad - eps_rad, bearing_rad + eps_rad, k)
    near = np.column_stack((r_min * np.cos(a), r_min * np.sin(a)))
    far = np.column_stack((r_max * np.cos(a[::-1]), r_max * np.sin(a[::-1])))
    out: NDArray[np.float64] = np.vstack((near, far)) + origin
    return out


def _clip(
    poly: list[tuple[float, float]], nx: float, ny: float, c: float
) -> list[tuple[float, float]]:
    """Sutherland-Hodgman: keep the part of a convex polygon with ``nx x + ny y <= c``."""
    out: list[tuple[float, float]] = []
    m = len(poly)
    for i in range(m):
        p, q = poly[i], poly[(i + 1) % m]
        fp = nx * p[0] + ny * p[1] - c
        fq = nx * q[0] + ny * q[1] - c
        if fp <= 0.0:
            out.append(p)
        if (fp < 0.0 < fq) or (fq < 0.0 < fp):
            t = fp / (fp - fq)
            out.append((p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])))
    return out


def _wedge_halfplanes(
    origin: NDArray[np.float64], bearing_rad: float, eps_rad: float
) -> list[tuple[float, float, float]]:
    """The wedge as two half-planes ``n . p <= c``."""
    ox, oy = float(origin[0]), float(origin[1])
    lo, hi = bearing_rad - eps_rad, bearing_rad + eps_rad
    # left of the lower edge: cross(u_lo, p - O) >= 0  <=>  (sin lo, -cos lo) . (p - O) <= 0
    n1 = (math.sin(lo), -math.cos(lo))
    # right of the upper edge: cross(u_hi, p - O) <= 0  <=>  (-sin hi, cos hi) . (p - O) <= 0
    n2 = (-math.sin(hi), math.cos(hi))
    return [(n[0], n[1], n[0] * ox + n[1] * oy) for n in (n1, n2)]


def _dist_to_convex(poly: NDArray[np.float64], pt: NDArray[np.float64]) -> tuple[float, float]:
    """(min, max) distance from ``pt`` to a convex polygon (min = 0 when inside)."""
    d_max = float(np.sqrt(((poly - pt) ** 2).sum(axis=1)).max())
    a = poly
    b = np.roll(poly, -1, axis=0)
    ab = b - a
    cross = ab[:, 0] * (pt[1] - a[:, 1]) - ab[:, 1] * (pt[0] - a[:, 0])
    if np.all(cross >= 0.0):  # counter-clockwise polygon, point inside
        return 0.0, d_max
    L2 = (ab * ab).sum(axis=1)
    t = np.clip(((pt - a) * ab).sum(axis=1) / np.where(L2 > 0, L2, 1.0), 0.0, 1.0)
    proj = a + t[:, None] * ab
    return float(np.sqrt(((proj - pt) ** 2).sum(axis=1)).min()), d_max


@dataclass(frozen=True)
class ConeIntersection:
    """``A_i``: the convex wedge intersection ``polygon`` (k, 2) FR, CCW, and the range bounds.

    Attributes
    ----------
    polygon : ndarray (k, 2)
        Intersection of the two infinite wedges, clipped to the box ``|x|, |y| <= r_max``.
    bearings_rad : (float, float)
        Bearings at O1 and O2.
    parallax_rad : float
        ``wrap(b2 - b1)``: the angle the baseline subtends at the landmark.
    cut_by_r_max : bool
        True when ``r_max`` (not the bearings) bounds part of the region (a wide, honest PDF).
    """

    polygon: NDArray[np.float64]
    bearings_rad: tuple[float, float]
    eps_rad: float
    r_min: float
    r_max: float
    parallax_rad: float
    cut_by_r_max: bool

    def _in_ranges(self, pts: NDArray[np.float64]) -> NDArray[np.bool_]:
        x, y = pts[:, 0], pts[:, 1]
        r1 = x * x + y * y
        r2 = (x - 1.0) * (x - 1.0) + y * y
        lo, hi = self.r_min * self.r_min, self.r_max * self.r_max
        ok: NDArray[np.bool_] = (r1 >= lo) & (r1 <= hi) & (r2 >= lo) & (r2 <= hi)
        return ok

    def contains(self, pts: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Whether each point (n, 2) FR lies in ``A_i`` (both cones, both range bounds)."""
        p = np.asarray(pts, dtype=np.float64)
        ok = self._in_ranges(p)
        b1, b2 = self.bearings_rad
        for o, b in ((O1_FR, b1), (O2_FR, b2)):
            for nx, ny, c in _wedge_halfplanes(o, b, self.eps_rad):
                ok &= nx * p[:, 0] + ny * p[:, 1] <= c + 1e-12
        return ok

    def sample_uniform(
        self, n: int, rng: np.random.Generator, max_rounds: int = 20
    ) -> NDArray[np.float64]:
        """Up to ``n`` points (k, 2) uniform in ``A_i`` (fewer only if ``A_i`` is a sliver)."""
        poly = self.polygon
        a = poly[0]
        e1 = poly[1:-1] - a
        e2 = poly[2:] - a
        area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
        cdf = np.cumsum(area)
        cdf /= cdf[-1]
        got: list[NDArray[np.float64]] = []
        have = 0
        m = n
        for _ in range(max_rounds):
            tri = np.minimum(np.searchsorted(cdf, rng.random(m), side="right"), cdf.size - 1)
            u = rng.random((m, 2))
            flip = u.sum(axis=1) > 1.0
            u[flip] = 1.0 - u[flip]
            pts = a + u[:, :1] * e1[tri] + u[:, 1:] * e2[tri]
            pts = pts[self._in_ranges(pts)]
            got.append(pts)
            have += pts.shape[0]
            if have >= n:
                break
            m = 2 * m
        return np.vstack(got)[:n]


def intersect_cones(
    bearing_o1_rad: float,
    bearing_o2_rad: float,
    eps_rad: float,
    r_min: float,
    r_max: float,
) -> ConeIntersection | Degenerate:
    """``A_i`` from the bearings at O1 = (0, 0) and O2 = (1, 0) in FR, or why it is degenerate."""
    if not (math.isfinite(bearing_o1_rad) and math.isfinite(bearing_o2_rad)):
        return Degenerate("bearing is not a finite number")
    b1, b2 = wrap_rad(float(bearing_o1_rad)), wrap_rad(float(bearing_o2_rad))
    parallax = float(wrap_rad(b2 - b1))
    if abs(parallax) <= 2.0 * eps_rad:
        return Degenerate(
            f"cones nearly parallel (parallax {math.degrees(parallax):.1f} deg <= 2 eps = "
            f"{math.degrees(2 * eps_rad):.1f} deg): landmark near the line of motion or too far"
        )
    # the bounded wedge intersection lies within 1 / sin(|parallax| - 2 eps) of O1 (law of sines)
    R = max(r_max, 2.0 / math.sin(min(abs(parallax) - 2.0 * eps_rad, 0.5 * math.pi)))
    poly: list[tuple[float, float]] = [(-R, -R), (R, -R), (R, R), (-R, R)]
    for o, b in ((O1_FR, b1), (O2_FR, b2)):
        for nx, ny, c in _wedge_halfplanes(o, b, eps_rad):
            poly = _clip(poly, nx, ny, c)
            if len(poly) < 3:
                return Degenerate("the two vision cones do not meet (bearings diverge)")
    arr = np.asarray(poly, dtype=np.float64)
    e1 = arr[1:-1] - arr[0]
    e2 = arr[2:] - arr[0]
    if float(np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()) <= 0.0:
        return Degenerate("the two vision cones meet only at a point or a line")
    cut = False
    for o in (O1_FR, O2_FR):
        d_min, d_max = _dist_to_convex(arr, o)
        if d_min > r_max:
            return Degenerate(f"the cones meet only farther than r_max = {r_max:g} movements")
        if d_max < r_min:
            return Degenerate(f"the cones meet only nearer than r_min = {r_min:g} movements")
        cut = cut or d_max > r_max
    if r_max < R:  # keep the sampling polygon within the r_max box
        for nx, ny in ((1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)):
            poly = _clip(poly, nx, ny, r_max)
        arr = np.asarray(poly, dtype=np.float64)
    return ConeIntersection(arr, (b1, b2), eps_rad, r_min, r_max, parallax, cut)
