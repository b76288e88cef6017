"""The bearing noise of a map, estimated from its residuals.

Point estimate (the noise model of the graph, the Huber threshold, association's predictions):
``sigma^2 = (sum_inliers r^2 + NU0 sigma0^2) / (dof + NU0)``: the residual variance with the
degrees of freedom the fit used up, shrunk towards the prior guess ``sigma0`` by ``NU0`` pseudo
observations (so a map with hardly any redundancy keeps the prior guess). Inliers: residuals
within :data:`OUTLIER_K` robust standard deviations (1.4826 x median absolute residual, floored at
:data:`FLOOR_RAD`) of zero.

What the covariances are scaled by: the posterior mean of ``sigma^2`` (:func:`posterior_variance`)
with a log-uniform prior on ``sigma`` between :data:`FLOOR_RAD` and the bearing error bound eps
(an error bounded by eps has a std of at most eps; log-uniform: no scale preferred). Each
landmark's covariance is then the covariance of its posterior with the noise scale unknown (a
Student-t, which a Gaussian of the same covariance stands for): with few degrees of freedom it is
wider than the point estimate's (``sum r^2 / (dof - 2)`` rather than ``/ dof``), and no prior guess
pulls a map of precise bearings towards eps.
"""

from __future__ import annotations

import functools
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
#: Points of the grid in log sigma on which the posterior of sigma is summed.
POSTERIOR_GRID = 2000


def robust_std(residuals_rad: NDArray[np.float64]) -> float:
    """Robust standard deviation of residuals (k,): 1.4826 x their median absolute value (the
    std of a Gaussian with that median; wrong detections barely move it)."""
    a = np.abs(residuals_rad)
    if a.size == 0:
        return 1.4826 * float(np.median(a))  # nan, as numpy's median says
    # numpy's median without its wrapping: the middle one or two of a partition (and the
    # largest, which is nan when any is)
    half = a.size // 2
    middle = (half,) if a.size % 2 else (half - 1, half)
    part = np.partition(a, (*middle, -1))
    if np.isnan(part[-1]):
        return math.nan
    mid = part[half] if a.size % 2 else (part[half - 1] + part[half]) / 2
    return 1.4826 * float(mid)


def robust_rms(residuals_rad: NDArray[np.float64]) -> float:
    """The robust RMS (rad) of residuals (k,) that the noise estimate reports
    (:attr:`NoiseEstimate.robust_rms_rad`): :func:`robust_std`, at least :data:`FLOOR_RAD`
    (0 without residuals)."""
    if residuals_rad.size == 0:
        return 0.0
    return max(robust_std(residuals_rad), FLOOR_RAD)


def posterior_variance(ssr_rad2: float, dof: int, bound_rad: float) -> float:
    """Posterior mean of ``sigma^2`` (rad^2) given ``dof`` degrees of freedom of residuals whose
    squares sum to ``ssr_rad2``, under a log-uniform prior on ``sigma`` in
    [:data:`FLOOR_RAD`, ``bound_rad``].

    The likelihood of ``sigma``, the map's unknowns integrated out (flat priors, linearized), is
    ``sigma^-dof exp(-ssr / (2 sigma^2))``; in ``u = log sigma`` the prior is flat, so the
    posterior is that likelihood, summed on a grid of ``u`` (:data:`POSTERIOR_GRID` points,
    trapezoidal rule).
    """
    u, inv_var, var = _grid(math.log(max(bound_rad, FLOOR_RAD * 1.001)))
    log_w = -max(dof, 0) * u - 0.5 * max(ssr_rad2, 0.0) * inv_var
    w = np.exp(log_w - log_w.max())
    w[[0, -1]] *= 0.5  # the trapezoidal rule
    return float((w * var).sum() / w.sum())


@functools.lru_cache(maxsize=8)
def _grid(
    hi: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The grid of :func:`posterior_variance` up to log sigma ``hi``: ``u = log sigma``,
    ``sigma^-2`` and ``sigma^2`` (:data:`POSTERIOR_GRID`,) each (read-only: shared)."""
    u = np.linspace(math.log(FLOOR_RAD), hi, POSTERIOR_GRID)
    out = u, np.exp(-2.0 * u), np.exp(2.0 * u)
    for a in out:
        a.setflags(write=False)
    return out


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
    variance_rad2 : float
        Posterior mean of the noise variance (:func:`posterior_variance`; ``sigma_rad ** 2``
        when no bound was given): what covariances are scaled by.
    """

    sigma_rad: float
    robust_rms_rad: float
    rms_rad: float
    n_bearings: int
    n_outliers: int
    dof: int
    variance_rad2: float


def estimate_noise(
    residuals_rad: NDArray[np.float64],
    n_params: int,
    sigma0_rad: float,
    bound_rad: float | None = None,
) -> NoiseEstimate:
    """Noise estimate from the bearing residuals (k,) of a fit with ``n_params`` free parameters;
    ``bound_rad``: the bearing error bound eps, for :attr:`NoiseEstimate.variance_rad2`."""
    r = np.asarray(residuals_rad, np.float64)
    if r.size == 0:
        var0 = sigma0_rad**2 if bound_rad is None else posterior_variance(0.0, 0, bound_rad)
        return NoiseEstimate(sigma0_rad, 0.0, 0.0, 0, 0, -n_params, var0)
    robust = robust_rms(r)
    inlier = np.abs(r) <= OUTLIER_K * max(robust, sigma0_rad * 0.25)
    ssr = float((r[inlier] ** 2).sum())
    dof = int(inlier.sum()) - n_params
    var = (ssr + NU0 * sigma0_rad**2) / (max(dof, 0) + NU0)
    sigma = max(math.sqrt(var), FLOOR_RAD)
    return NoiseEstimate(
        sigma,
        robust,
        float(np.sqrt(np.mean(r**2))),
        int(r.size),
        int((~inlier).sum()),
        dof,
        sigma**2 if bound_rad is None else posterior_variance(ssr, dof, bound_rad),
    )
