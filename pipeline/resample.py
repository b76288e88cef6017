"""Systematic resampling (one uniform draw, ``n`` evenly spaced pointers)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from data_schemas.errors import EstimationError


def systematic_resample(
    weights: NDArray[np.float64], n: int, rng: np.random.Generator
) -> NDArray[np.intp]:
    """Indices (n,) into ``weights`` (k,), each index drawn ``n w_i / sum(w)`` times on average.

    Unbiased (the expected count of index i is exactly ``n w_i / sum w``) with the lowest
    variance of the standard schemes. Raises :class:`EstimationError` if the weights do not sum
    to a positive finite number.
    """
    w = np.asarray(weights, dtype=np.float64)
    total = float(w.sum())
    if not (total > 0.0 and np.isfinite(total)) or np.any(w < 0.0):
        raise EstimationError("resampling needs non-negative weights with a positive finite sum")
    cdf = np.cumsum(w)
    pointers = (rng.random() + np.arange(n)) * (total / n)
    idx = np.searchsorted(cdf, pointers, side="right")
    out: NDArray[np.intp] = np.minimum(idx, w.size - 1)
    return out
