"""Pinhole pixels to bearings: OpenCV undistortion, then ``bearing = offset - atan(xn)``.

The calibration's parameters and the bearing formula are in
:class:`data_schemas.calibration.PinholeCalibration`; this module applies OpenCV's inverse of the
distortion model (``cv2.undistortPoints``, or ``cv2.fisheye.undistortPoints`` for
``equidistant``), iterated to convergence rather than OpenCV's default of a few steps.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from numpy.typing import NDArray

from data_schemas.calibration import Calibration, PinholeCalibration

#: Undistortion stops after this many iterations or a step below this size (normalized units).
_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)


def undistort_pixels(
    calibration: PinholeCalibration, x: NDArray[np.floating], y: NDArray[np.floating]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Undistorted normalized image coordinates ``(xn, yn)`` of continuous pixel coordinates.

    Parameters
    ----------
    calibration : PinholeCalibration
    x, y : ndarray, same shape
        Continuous pixel coordinates (pixel ``(i, j)`` covers ``[j, j + 1) x [i, i + 1)``, its
        centre ``(j + 0.5, i + 0.5)``; OpenCV's coordinates are these minus 0.5).

    Returns
    -------
    xn, yn : ndarray, the shape of ``x``
        Normalized coordinates of the ray (x right, y down, z along the optical axis = 1).
    """
    x_arr = np.asarray(x, np.float64)
    pts = np.stack([x_arr.ravel() - 0.5, np.asarray(y, np.float64).ravel() - 0.5], axis=-1)
    pts = pts.reshape(-1, 1, 2)
    k = calibration.camera_matrix
    d = np.asarray(calibration.distortion, np.float64)
    if calibration.distortion_model == "equidistant":
        d4 = d if d.size else np.zeros(4)
        out = cv2.fisheye.undistortPoints(pts, k, d4, criteria=_CRITERIA)
    elif hasattr(cv2, "undistortPointsIter"):  # OpenCV 4: the iterations' criteria go here
        out = cv2.undistortPointsIter(pts, k, d if d.size else None, None, None, _CRITERIA)
    else:
        out = cv2.undistortPoints(pts, k, d if d.size else None, criteria=_CRITERIA)
    xy = np.asarray(out, np.float64).reshape(-1, 2)
    return xy[:, 0].reshape(x_arr.shape), xy[:, 1].reshape(x_arr.shape)


def pixel_bearings(
    calibration: PinholeCalibration, x: NDArray[np.floating], y: NDArray[np.floating]
) -> NDArray[np.float64]:
    """Bearing (rad, [-pi, pi), robot frame) of continuous pixel coordinates (any shape)."""
    xn, _ = undistort_pixels(calibration, x, y)
    return calibration.bearing_of_normalized(xn)


def pixel_rays(
    calibration: PinholeCalibration, x: NDArray[np.floating], y: NDArray[np.floating]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Bearing (rad, [-pi, pi), robot frame) and elevation (rad, up positive) of continuous pixel
    coordinates (any shape) of a level camera."""
    xn, yn = undistort_pixels(calibration, x, y)
    return calibration.bearing_of_normalized(xn), np.arctan2(-yn, np.hypot(xn, 1.0))


def field_of_view_rad(calibration: PinholeCalibration) -> tuple[float, float]:
    """Bearings (rad, robot frame) of the image's right and left edges: ``(lo, hi)``.

    The extreme bearings along the image border (distortion may bend the edges), so a point at
    bearing ``b`` is in view when ``wrap(b - lo) <= hi - lo``.
    """
    w, h = calibration.width, calibration.height
    ys = np.linspace(0.0, h, max(2, h // 4 + 1))
    xs = np.linspace(0.0, w, max(2, w // 4 + 1))
    border_x = np.concatenate([np.zeros_like(ys), np.full_like(ys, w), xs, xs])
    border_y = np.concatenate([ys, ys, np.zeros_like(xs), np.full_like(xs, h)])
    rel = pixel_bearings(calibration, border_x, border_y) - calibration.offset_rad
    rel = (rel + math.pi) % (2.0 * math.pi) - math.pi
    return calibration.offset_rad + float(rel.min()), calibration.offset_rad + float(rel.max())


def camera_view_rad(calibration: Calibration | None) -> tuple[float, float] | None:
    """The field of view ``(lo, hi)`` of a pinhole camera (:func:`field_of_view_rad`); None for
    a panoramic one or none."""
    if isinstance(calibration, PinholeCalibration):
        return field_of_view_rad(calibration)
    return None


def bearing_polyline(
    calibration: PinholeCalibration, bearing_rad: float, n_points: int = 9
) -> NDArray[np.float64] | None:
    """Pixels (continuous coordinates, (n_points, 2), x right, y down) along which a vertical
    line at ``bearing_rad`` projects into the image (bent by distortion); None if behind."""
    rel = float(bearing_rad) - calibration.offset_rad
    rel = (rel + math.pi) % (2.0 * math.pi) - math.pi
    if abs(rel) >= 0.5 * math.pi - 1e-3:
        return None
    half_h = 0.5 * calibration.height / calibration.fy
    y = np.linspace(-half_h, half_h, n_points)
    pts = np.stack([np.full(n_points, -math.sin(rel)), y, np.full(n_points, math.cos(rel))], 1)
    pts = pts.reshape(-1, 1, 3)
    zero = np.zeros(3)
    k = calibration.camera_matrix
    d = np.asarray(calibration.distortion, np.float64)
    if calibration.distortion_model == "equidistant":
        uv, _ = cv2.fisheye.projectPoints(pts, zero, zero, k, d if d.size else np.zeros(4))
    else:
        uv, _ = cv2.projectPoints(pts, zero, zero, k, d if d.size else None)
    out: NDArray[np.float64] = np.asarray(uv, np.float64).reshape(-1, 2) + 0.5
    return out
