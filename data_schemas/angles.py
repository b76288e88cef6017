"""The project's angle convention: radians, counter-clockwise positive, wrapped to [-pi, pi)."""

from __future__ import annotations

import math
from typing import overload

import numpy as np
from numpy.typing import NDArray

TWO_PI = 2.0 * math.pi


@overload
def wrap_rad(angle_rad: float) -> float: ...
@overload
def wrap_rad(angle_rad: NDArray[np.floating]) -> NDArray[np.float64]: ...
def wrap_rad(angle_rad: float | NDArray[np.floating]) -> float | NDArray[np.float64]:
    """Wrap angles to [-pi, pi).

    Uses a floor-based wrap (numpy's float ``%`` is about 10x slower).

    Parameters
    ----------
    angle_rad : float or ndarray, any shape
        Angles in radians.

    Returns
    -------
    float or ndarray of the same shape
        The same angles in [-pi, pi).
    """
    if isinstance(angle_rad, float | int):
        return float(angle_rad - TWO_PI * math.floor((angle_rad + math.pi) / TWO_PI))
    a = np.asarray(angle_rad, dtype=np.float64)
    return a - TWO_PI * np.floor((a + math.pi) * (1.0 / TWO_PI))


def truncated_normal_std(std: float, bound: float) -> float:
    """Standard deviation of N(0, std^2) truncated to ``[-bound, bound]``.

    The bearing noise model of the method (a Gaussian cut at the vision error bound eps): the
    simulator draws it, the Cramér–Rao yardstick and the experiments use its actual std.
    """
    if std <= 0:
        return 0.0
    k = bound / std
    pdf = math.exp(-0.5 * k * k) / math.sqrt(TWO_PI)
    mass = math.erf(k / math.sqrt(2.0))
    return std * math.sqrt(1.0 - 2.0 * k * pdf / mass)
