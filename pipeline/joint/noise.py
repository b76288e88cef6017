"""The bearing noise of a map, estimated from its residuals.

``sigma^2 = (sum_inliers r^2 + NU0 sigma0^2) / (dof + NU0)``: the residual variance with the
degrees of freedom the fit used up, shrunk towards the prior guess ``sigma0`` by ``NU0`` pseudo
observations (so a map with hardly any redundancy keeps the prior guess). Inliers: residuals
within :data:`OUTLIER_K` robust standard deviations (1.4826 x median absolute residual, floored at
:data:`FLOOR_RAD`) of zero.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

#: Pseudo observations of the prior guess.
NU0 = 0.5
#: Residuals beyond this many robust standard deviations do not count (wrong detections).
OUTLIER_K = 4.0
#: Smallest noise the estimate reports (rad): 0.02 deg.
FLOOR_RAD = math.radians(0.02)


def robust_std(residuals_rad: NDArray[np.float64]) -> float:
    """Robust standard deviation of residuals (k,): 1.4826 x their median absolute value (the
    std of a Gaussian with that median; wrong detections barely move it)."""
    return 1.4826 * float(np.median(np.abs(residuals_rad)))


@dataclass(frozen=True)
class NoiseEstimate:
    """Bearing noise estimated from the residuals of a map.

    Attributes
    ----------
    sigma_rad : float
        Estimated std of the bearing error.
    robust_rms_rad : float
        1.4826 x median absolute residual (what the divergence check compares with eps).
    rms_rad : float
        RMS of all residuals.
    n_bearings : int
        Residuals counted.
    n_outliers : int
        Residuals left out as wrong detections.
    dof : int
        Bearings minus free parameters (negative: not enough redundancy yet).
    """

    sigma_rad: float
    robust_rms_rad: float
    rms_rad: float
    n_bearings: int
    n_outliers: int
    dof: int


def estimate_noise(
    residuals_rad: NDArray[np.float64], n_params: int, sigma0_rad: float
) -> NoiseEstimate:
    """Noise estimate from the bearing residuals (k,) of a fit with ``n_params`` free parameters."""
    r = np.asarray(residuals_rad, np.float64)
    if r.size == 0:
        return NoiseEstimate(sigma0_rad, 0.0, 0.0, 0, 0, -n_params)
    robust = max(robust_std(r), FLOOR_RAD)
    inlier = np.abs(r) <= OUTLIER_K * max(robust, sigma0_rad * 0.25)
    ssr = float((r[inlier] ** 2).sum())
    dof = int(inlier.sum()) - n_params
    var = (ssr + NU0 * sigma0_rad**2) / (max(dof, 0) + NU0)
    return NoiseEstimate(
        max(math.sqrt(var), FLOOR_RAD),
        robust,
        float(np.sqrt(np.mean(r**2))),
        int(r.size),
        int((~inlier).sum()),
        dof,
    )
