"""Cramér–Rao bound for bearing-only triangulation (docs/method.md, part 8).

Fisher information of a landmark at ``x`` from bearings taken at known points ``o_i`` with
independent noise of std ``sigma``: ``J = sum n_i n_i^T / (sigma^2 r_i^2)``, ``n_i`` the unit
normal to the line of sight, ``r_i`` its length. The bound on the covariance is ``J^-1``.
Bounded (truncated) noise breaks the regularity conditions; use the bound with the noise's
actual std (:func:`truncated_gaussian_std`) as a Gaussian-equivalent yardstick.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import truncated_normal_std


def truncated_gaussian_std(eps_rad: float, sigma_frac: float = 0.5) -> float:
    """Std (rad) of a Gaussian of std ``sigma_frac * eps`` truncated to ``[-eps, eps]``."""
    return truncated_normal_std(sigma_frac * eps_rad, eps_rad)


def fisher_information(
    landmark: NDArray[np.float64], observers: NDArray[np.float64], sigma_rad: float
) -> NDArray[np.float64]:
    """``J`` (2, 2) of a landmark (2,) seen from observers (k, 2), bearing std ``sigma_rad``."""
    d = np.asarray(landmark, dtype=np.float64) - np.asarray(observers, dtype=np.float64)
    r2 = (d * d).sum(axis=1)
    n = np.column_stack((-d[:, 1], d[:, 0])) / r2[:, None]  # unit normal / r
    out: NDArray[np.float64] = (n.T @ n) / (sigma_rad * sigma_rad)
    return out


def cramer_rao_bound(
    landmark: NDArray[np.float64], observers: NDArray[np.float64], sigma_rad: float
) -> NDArray[np.float64]:
    """Lower bound (2, 2) on the covariance of any unbiased position estimate (inf if singular)."""
    j = fisher_information(landmark, observers, sigma_rad)
    det = float(j[0, 0] * j[1, 1] - j[0, 1] * j[1, 0])
    if not det > 1e-300:
        return np.full((2, 2), np.inf)
    return np.array([[j[1, 1], -j[0, 1]], [-j[1, 0], j[0, 0]]]) / det
