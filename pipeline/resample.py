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
    variance of the standard schemes. The pointers ``(u + m) sum(w) / n`` are counted per
    weight (``ceil`` of the scaled cumulative sum) instead of searched one by one; the
    indices come out sorted. Raises :class:`EstimationError` if the weights do not sum to a
    positive finite number.
    """
    w = np.asarray(weights, dtype=np.float64)
    cdf = np.cumsum(w)
    total = float(cdf[-1]) if cdf.size else 0.0
    if not (total > 0.0 and np.isfinite(total)) or float(w.min()) < 0.0:
        raise EstimationError("resampling needs non-negative weights with a positive finite sum")
    # pointers below cdf_i: ceil(cdf_i n / total - u), in [0, n] (the last one is n)
    below = cdf
    below *= n / total
    below -= rng.random()
    np.ceil(below, out=below)
    below[-1] = n
    counts = np.empty(w.size, np.intp)
    counts[0] = below[0]
    np.subtract(below[1:], below[:-1], out=counts[1:], casting="unsafe")
    out: NDArray[np.intp] = np.repeat(np.arange(w.size), counts)
    return out
