"""Predicted bearings of mapped points and their uncertainty (FL, rad).

:func:`predict_bearings` and :func:`predict_ranges` are the first-order predictions;
:class:`BearingModel` holds what association adds to them (the bearing noise of a detection
and of the landmark's own bearings, the camera's view), and :func:`predict_named` predicts the
named landmarks of one class from one keyframe for the per-movement assignment
(:func:`pipeline.association.assign.assign_movement`).
"""

from __future__ import annotations

import math
from collections.abc import Collection, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad
from pipeline.crb import truncated_gaussian_std
from pipeline.estimate import LandmarkEstimate

#: A named landmark whose predicted bearing is less certain than this (std, in eps) is too
#: poorly placed to gate detections: reported, left out of the assignment.
MAX_PRED_STD_EPS = 2.0
#: Chi-square gate, one degree of freedom, 99.9 % (a detection within it of a prediction is
#: plausibly that landmark).
GATE_CHI2 = 10.83


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


@dataclass(frozen=True)
class BearingModel:
    """How association predicts bearings: the bearing error bound, its noise, the camera's view.

    Attributes
    ----------
    eps_rad : float
        The bearing error bound eps.
    field_of_view_rad : (lo, hi) or None
        A pinhole camera's view, bearings of its right and left edges (rad, robot frame); None:
        a panoramic camera.
    """

    eps_rad: float
    field_of_view_rad: tuple[float, float] | None = None
    sigma_rad: float = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "sigma_rad", truncated_gaussian_std(self.eps_rad))

    def predict(
        self,
        points_fl: NDArray[np.float64],
        covs_fl: NDArray[np.float64],
        origin_fl: NDArray[np.float64],
        heading_rad: float | NDArray[np.float64],
        pos_var_fl: float,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Predicted bearings (n,) of points (n, 2) with covariances (n, 2, 2) from a keyframe
        whose position has variance ``pos_var_fl`` (FL^2) along any direction, and their stds:
        :func:`predict_bearings` with the noise of the detection and of the bearings that placed
        the point (``2 sigma^2``)."""
        return predict_bearings(
            origin_fl,
            heading_rad,
            points_fl,
            covs_fl,
            origin_var_fl=pos_var_fl,
            bearing_var_rad=2.0 * self.sigma_rad**2,
        )

    def outside(self, pred: NDArray[np.float64], std: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Predictions (n,) outside the camera's view by more than their gate."""
        return outside_view(pred, std, self.field_of_view_rad, n_std=math.sqrt(GATE_CHI2))

    def vague(self, std: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Predictions (n,) too uncertain to gate detections (:data:`MAX_PRED_STD_EPS`)."""
        out: NDArray[np.bool_] = std > MAX_PRED_STD_EPS * self.eps_rad
        return out


@dataclass(frozen=True)
class Predicted:
    """Named landmarks of one class predicted from one keyframe.

    Attributes
    ----------
    names : list of str
        The landmarks predicted sharply enough and in view: the ones the assignment takes.
    bearing_rad, std_rad : (n,) float
        Their predicted bearings (robot frame) and stds, rad.
    range_fl, range_std_fl : (n,) float
        Their predicted distances and stds (FL); NaN distance for a name not trusted to hide
        others.
    vague : list of (str, float)
        Names predicted too uncertainly to gate, with the std (rad).
    away : list of (str, float)
        Names predicted outside the camera's view, with the bearing (rad).
    """

    names: list[str]
    bearing_rad: NDArray[np.float64]
    std_rad: NDArray[np.float64]
    range_fl: NDArray[np.float64]
    range_std_fl: NDArray[np.float64]
    vague: list[tuple[str, float]] = field(default_factory=list)
    away: list[tuple[str, float]] = field(default_factory=list)


def predict_named(
    known: Sequence[tuple[str, LandmarkEstimate]],
    origin_fl: NDArray[np.float64],
    heading_rad: float,
    pos_var_fl: float,
    model: BearingModel,
    trusted: Collection[str],
) -> Predicted:
    """The bearings of named landmarks ``known`` (name, estimate in FL) from a keyframe at
    ``origin_fl`` (2,) with heading ``heading_rad`` whose position has variance
    ``pos_var_fl`` (FL^2); distances only for the ``trusted`` names (in the map and
    confirmed: the ones that may hide others)."""
    if not known:
        empty = np.zeros(0)
        return Predicted([], empty, empty, empty, empty)
    pts = np.array([e.mean_fl for _, e in known])
    covs = np.array([e.cov_fl for _, e in known])
    pred, std = model.predict(pts, covs, origin_fl, heading_rad, pos_var_fl)
    vague = model.vague(std)
    away = model.outside(pred, std)
    sharp = np.flatnonzero(~vague & ~away)
    usable = [known[int(i)] for i in sharp]
    range_fl, range_std_fl = predict_ranges(
        origin_fl,
        np.array([e.mean_fl for _, e in usable]),
        np.array([e.cov_fl for _, e in usable]),
        origin_var_fl=pos_var_fl,
    )
    return Predicted(
        [n for n, _ in usable],
        pred[sharp],
        std[sharp],
        np.where([n in trusted for n, _ in usable], range_fl, np.nan),
        range_std_fl,
        vague=[(known[int(k)][0], float(std[k])) for k in np.flatnonzero(vague)],
        away=[(known[int(k)][0], float(pred[k])) for k in np.flatnonzero(away & ~vague)],
    )
