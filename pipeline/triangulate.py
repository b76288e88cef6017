"""Two-view triangulation in a movement's frame FR (O1 = (0, 0), O2 = (1, 0))."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

#: Minimal parallax (rad) for a triangulation to count.
MIN_PARALLAX_RAD = math.radians(1.0)


def triangulate_fr(b1_rad: float, b2_rad: float) -> NDArray[np.float64] | None:
    """Intersection (2,) FR of the rays from (0,0) and (1,0), or None if they do not meet ahead."""
    s = math.sin(b2_rad - b1_rad)
    if abs(s) < math.sin(MIN_PARALLAX_RAD):
        return None
    r1 = math.sin(b2_rad) / s
    r2 = math.sin(b1_rad) / s
    if r1 <= 0.0 or r2 <= 0.0:
        return None
    return np.array([r1 * math.cos(b1_rad), r1 * math.sin(b1_rad)])
