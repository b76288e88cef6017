"""The simulator's own pinhole lens: OpenCV's distortion models, written out, and their inverse.

The simulated camera needs the ray of every pixel of a distorted image. It computes it here,
from the distortion models as OpenCV documents them, inverted by Newton's method, and not
through OpenCV's ``undistortPoints`` that bearing extraction uses: the simulated frames are then
an independent check of the extraction. Normalized coordinates: x right, y down, z = 1 along
the optical axis.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from data_schemas.calibration import PinholeCalibration

Array = NDArray[np.float64]


def distort(cal: PinholeCalibration, x: Array, y: Array) -> tuple[Array, Array]:
    """Distorted normalized coordinates of undistorted normalized ``(x, y)`` (any shape)."""
    d = list(cal.distortion)
    if cal.distortion_model == "equidistant":
        k1, k2, k3, k4 = d if d else (0.0, 0.0, 0.0, 0.0)
        r = np.hypot(x, y)
        theta = np.arctan(r)
        t2 = theta * theta
        theta_d = theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
        scale = np.where(r > 1e-12, theta_d / np.maximum(r, 1e-12), 1.0)
        return x * scale, y * scale
    d += [0.0] * (8 - len(d))
    k1, k2, p1, p2, k3, k4, k5, k6 = d
    r2 = x * x + y * y
    radial = (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return xd, yd


def project(cal: PinholeCalibration, x: Array, y: Array) -> tuple[Array, Array]:
    """Continuous pixel coordinates (pixel centres at ``j + 0.5``) of normalized rays."""
    xd, yd = distort(cal, x, y)
    return cal.fx * xd + cal.cx + 0.5, cal.fy * yd + cal.cy + 0.5


def rays_of_pixels(
    cal: PinholeCalibration, u: Array, v: Array, *, iterations: int = 30
) -> tuple[Array, Array]:
    """Undistorted normalized rays of continuous pixel coordinates ``(u, v)`` (any shape).

    Newton's method on :func:`distort`, with a central-difference Jacobian, from the distorted
    point itself.
    """
    xd = (np.asarray(u, np.float64) - 0.5 - cal.cx) / cal.fx
    yd = (np.asarray(v, np.float64) - 0.5 - cal.cy) / cal.fy
    if not any(cal.distortion):
        return xd, yd
    x, y = xd.copy(), yd.copy()
    h = 1e-7
    for _ in range(iterations):
        fx, fy = distort(cal, x, y)
        ex, ey = fx - xd, fy - yd
        ax, ay = distort(cal, x + h, y)
        bx, by = distort(cal, x - h, y)
        cx, cy = distort(cal, x, y + h)
        dx, dy = distort(cal, x, y - h)
        j11, j21 = (ax - bx) / (2 * h), (ay - by) / (2 * h)
        j12, j22 = (cx - dx) / (2 * h), (cy - dy) / (2 * h)
        det = j11 * j22 - j12 * j21
        det = np.where(np.abs(det) > 1e-12, det, 1e-12)
        x = x - (j22 * ex - j12 * ey) / det
        y = y - (j11 * ey - j21 * ex) / det
        if max(float(np.abs(ex).max(initial=0.0)), float(np.abs(ey).max(initial=0.0))) < 1e-13:
            break
    return x, y
