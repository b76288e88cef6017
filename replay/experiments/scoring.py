"""Score one landmark estimate (mean, covariance in FL) against the truth.

Every method is scored the same way, from its mean and covariance: the error is the Euclidean
distance to the truth, and the 80% region is the Gaussian ellipse of that covariance
(Mahalanobis distance squared at most ``-2 ln(1 - 0.8)``, the chi-square quantile with 2 dof).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from replay.experiments.results import ErrorRow
from replay.experiments.stats import LEVEL

#: chi-square(2) quantile at LEVEL: the squared Mahalanobis radius of the 80% ellipse
CHI2_2_LEVEL = -2.0 * math.log(1.0 - LEVEL)


def inside_region(mean_fl: ArrayLike, cov_fl: ArrayLike, point_fl: ArrayLike) -> bool | None:
    """Whether ``point_fl`` lies in the ``LEVEL`` Gaussian ellipse (None: covariance singular)."""
    cov = np.asarray(cov_fl, dtype=np.float64)
    d = np.asarray(point_fl, dtype=np.float64) - np.asarray(mean_fl, dtype=np.float64)
    if not np.all(np.isfinite(cov)) or np.linalg.det(cov) <= 0.0:
        return None
    return bool(d @ np.linalg.solve(cov, d) <= CHI2_2_LEVEL)


def score_rows(
    estimates: dict[str, tuple[ArrayLike, ArrayLike | None]],
    truth_fl: dict[str, NDArray[np.float64]],
    landmarks: list[str],
    *,
    scale_cm: float,
    group: str,
    run: int,
    method: str,
    n_l: int,
    movement: int,
) -> list[ErrorRow]:
    """One row per scored landmark; a landmark with no estimate gets NaN errors.

    Parameters
    ----------
    estimates : dict of str -> (mean (2,), cov (2, 2) or None)
        Estimates in FL (cov None: the method gives no region).
    truth_fl : dict of str -> ndarray (2,)
        True positions in FL.
    landmarks : list of str
        Which landmarks to score.
    scale_cm : float
        Centimetres per FL unit (the true |L1 L2|).
    """
    rows = []
    for name in landmarks:
        est = estimates.get(name)
        if est is None:
            rows.append(ErrorRow(group, run, method, n_l, movement, name, math.nan, math.nan, None))
            continue
        mean, cov = est
        err = float(np.hypot(*(np.asarray(mean, dtype=np.float64) - truth_fl[name])))
        inside = None if cov is None else inside_region(mean, cov, truth_fl[name])
        rows.append(ErrorRow(group, run, method, n_l, movement, name, err, err * scale_cm, inside))
    return rows
