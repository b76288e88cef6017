"""Predicted bearings of mapped points and their uncertainty (FL, rad)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad

#: A named landmark whose predicted bearing is less certain than this (std, in eps) is too
#: poorly placed to gate detections: reported, left out of the assignment.
MAX_PRED_STD_EPS = 2.0


def predict_bearings(
    origin_fl: NDArray[np.float64],
    heading_rad: float | NDArray[np.float64],
    points_fl: NDArray[np.float64],
    covs_fl: NDArray[np.float64],
    *,
    origin_var_fl: float = 0.0,
    bearing_var_rad: float = 0.0,
    pose_cov: NDArray[np.float64] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Bearing of each point seen from a keyframe, and its standard deviation.

    Parameters
    ----------
    origin_fl : (2,) or (n, 2) float
        Keyframe position, FL (or one per point).
    heading_rad : float or (n,) float
        Keyframe heading, FL (bearings are relative to it; or one per point).
    points_fl : (n, 2) float
        Point estimates, FL.
    covs_fl : (n, 2, 2) float
        Their covariances, FL^2.
    origin_var_fl : float
        Variance of the keyframe position along any direction, FL^2.
    bearing_var_rad : float
        Variance added to every prediction (measurement noise, heading), rad^2.
    pose_cov : (3, 3) float or None
        Covariance of the keyframe's ``(x, y, heading)`` in its own frame (FL^2, FL rad,
        rad^2; :class:`pipeline.geometry.KeyframePose`), taken as independent of the
        points'; ``heading_rad`` must then be one float.

    Returns
    -------
    bearing_rad : (n,) float
        Predicted bearings in [-pi, pi).
    std_rad : (n,) float
        First-order standard deviation of each prediction.
    """
    d = np.asarray(points_fl, np.float64).reshape(-1, 2) - np.asarray(origin_fl, np.float64)
    r2 = np.maximum((d**2).sum(axis=1), 1e-12)
    jac = np.column_stack((-d[:, 1], d[:, 0])) / r2[:, None]  # d bearing / d point, (n, 2)
    var = np.einsum("ni,nij,nj->n", jac, np.asarray(covs_fl, np.float64).reshape(-1, 2, 2), jac)
    var = var + origin_var_fl / r2 + bearing_var_rad
    if pose_cov is not None:
        c, s = math.cos(float(heading_rad)), math.sin(float(heading_rad))
        # d bearing / d (x, y, heading) of the keyframe, (x, y) in its own frame
        jac_pose = np.column_stack((-(jac @ np.array([[c, -s], [s, c]])), -np.ones(len(d))))
        var = var + np.einsum("ni,ij,nj->n", jac_pose, np.asarray(pose_cov, np.float64), jac_pose)
    bearing = wrap_rad(np.arctan2(d[:, 1], d[:, 0]) - heading_rad)
    return np.asarray(bearing, np.float64), np.sqrt(np.maximum(var, 0.0))


def outside_view(
    bearing_rad: NDArray[np.float64],
    std_rad: NDArray[np.float64],
    field_of_view_rad: tuple[float, float] | None,
    *,
    n_std: float,
) -> NDArray[np.bool_]:
    """Which predicted bearings lie outside a camera's field of view by more than ``n_std``
    standard deviations (such a landmark is not visible there, not missed).

    Parameters
    ----------
    bearing_rad, std_rad : (n,) float
        Predicted bearings (robot frame) and their standard deviations, rad.
    field_of_view_rad : (lo, hi) or None
        Bearings of the view's right and left edges, rad (``hi - lo`` its width); None: a
        panoramic camera, everything is in view.
    n_std : float
        Margin, in standard deviations of each prediction.
    """
    b = np.asarray(bearing_rad, np.float64).reshape(-1)
    if field_of_view_rad is None:
        return np.zeros(b.shape, np.bool_)
    lo, hi = field_of_view_rad
    margin = n_std * np.asarray(std_rad, np.float64).reshape(-1)
    # angle past the left edge and before the right edge, measured away from the view's middle
    centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    off = np.abs(wrap_rad(b - centre)) - half
    out: NDArray[np.bool_] = off > margin
    return out


def predict_ranges(
    origin_fl: NDArray[np.float64],
    points_fl: NDArray[np.float64],
    covs_fl: NDArray[np.float64],
    *,
    origin_var_fl: float = 0.0,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Distance (n,) of each point from a keyframe and its first-order std (FL).

    ``origin_fl`` (2,), ``points_fl`` (n, 2), ``covs_fl`` (n, 2, 2) FL^2; ``origin_var_fl`` the
    keyframe position's variance along any direction (FL^2).
    """
    v = np.asarray(points_fl, np.float64).reshape(-1, 2) - np.asarray(origin_fl, np.float64)
    range_fl = np.linalg.norm(v, axis=1)
    u = v / np.maximum(range_fl, 1e-12)[:, None]
    var = np.einsum("ni,nij,nj->n", u, np.asarray(covs_fl, np.float64).reshape(-1, 2, 2), u)
    return range_fl, np.sqrt(np.maximum(var + origin_var_fl, 0.0))


def ray_point_cov(
    point_fl: NDArray[np.float64], origins_fl: NDArray[np.float64], sigma_rad: float
) -> NDArray[np.float64]:
    """Covariance (2, 2) of a point fixed by bearings of std ``sigma_rad`` from ``origins_fl``.

    First order: each bearing from origin ``o`` constrains the point across the ray with
    information ``n n^T / (|p - o|^2 sigma^2)`` (``n`` the unit normal of the ray); a tiny
    ridge keeps the inverse finite when the rays are parallel.
    """
    d = np.asarray(point_fl, np.float64) - np.asarray(origins_fl, np.float64).reshape(-1, 2)
    dx, dy = d[:, 0], d[:, 1]
    w = 1.0 / (np.maximum(dx * dx + dy * dy, 1e-12) ** 2 * sigma_rad**2)  # 1 / (r^2 sigma)^2
    # information sum of n n^T w with n = (-dy, dx) / r, plus the ridge; inverted in closed form
    ixx = float(w @ (dy * dy)) + 1e-9
    ixy = -float(w @ (dx * dy))
    iyy = float(w @ (dx * dx)) + 1e-9
    det = ixx * iyy - ixy * ixy
    return np.array([[iyy, -ixy], [-ixy, ixx]]) / det
