"""Odometry between keyframes: relative poses (SE(2)) and the wheel noise model.

A pose is ``(x, y, theta)``: position (m) and heading (rad) in some frame. ``between(a, b)`` is
``b`` seen from ``a`` (the odometry increment, in ``a``'s body frame: x ahead, y left);
``compose(a, d)`` undoes it. The wheel model gives the std of an increment from the travel it
covers: each position component ``trans_std_per_m`` per metre of path, the heading
``rot_std_per_rad`` per radian turned plus ``rot_std_per_m`` per metre driven (slip while
driving), each with a floor so that no increment is exact.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad
from data_schemas.errors import EstimationError


def between(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Pose ``b`` (3,) seen from pose ``a`` (3,): (dx, dy) in ``a``'s body frame (m), dtheta."""
    c, s = math.cos(float(a[2])), math.sin(float(a[2]))
    dx, dy = float(b[0] - a[0]), float(b[1] - a[1])
    return np.array([c * dx + s * dy, -s * dx + c * dy, float(wrap_rad(float(b[2] - a[2])))])


def compose(a: NDArray[np.float64], d: NDArray[np.float64]) -> NDArray[np.float64]:
    """Pose ``a`` (3,) moved by the body-frame increment ``d`` (3,): the inverse of ``between``."""
    c, s = math.cos(float(a[2])), math.sin(float(a[2]))
    return np.array(
        [
            float(a[0]) + c * float(d[0]) - s * float(d[1]),
            float(a[1]) + s * float(d[0]) + c * float(d[1]),
            float(wrap_rad(float(a[2] + d[2]))),
        ]
    )


def interpolate(
    t_ns: int, t0_ns: int, p0: NDArray[np.float64], t1_ns: int, p1: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Pose at ``t_ns`` between poses ``p0`` at ``t0_ns`` and ``p1`` at ``t1_ns`` (linear in the
    body-frame increment; clamped to the ends)."""
    if t1_ns <= t0_ns or t_ns <= t0_ns:
        return np.asarray(p0, np.float64) if t_ns <= t0_ns else np.asarray(p1, np.float64)
    f = min(1.0, (t_ns - t0_ns) / (t1_ns - t0_ns))
    return compose(p0, f * between(p0, p1))


#: Default std of each position component per metre of path (m/m).
TRANS_STD_PER_M = 0.1
#: Default heading std per radian turned (rad/rad).
ROT_STD_PER_RAD = 0.2
#: Default heading std per metre driven (rad/m).
ROT_STD_PER_M = 0.05
#: Floors of the position (m) and heading (rad) stds.
FLOOR_M = 1e-3
FLOOR_RAD = 1e-3


@dataclass(frozen=True)
class WheelNoise:
    """Std of an odometry increment from the travel it covers (see the module doc).

    Attributes
    ----------
    trans_std_per_m : float
        Std (m) of each position component per metre of path.
    rot_std_per_rad : float
        Heading std (rad) per radian turned.
    rot_std_per_m : float
        Heading std (rad) per metre of path.
    """

    trans_std_per_m: float = TRANS_STD_PER_M
    rot_std_per_rad: float = ROT_STD_PER_RAD
    rot_std_per_m: float = ROT_STD_PER_M

    def __post_init__(self) -> None:
        for v in (self.trans_std_per_m, self.rot_std_per_rad, self.rot_std_per_m):
            if not (math.isfinite(v) and v >= 0.0):
                raise EstimationError(f"wheel noise must be a finite number >= 0, got {v}")

    def sigmas(self, path_m: float, turn_rad: float) -> NDArray[np.float64]:
        """Stds (3,) of an increment's (dx (m), dy (m), dtheta (rad)) after ``path_m`` of path and
        ``turn_rad`` of turning (absolute)."""
        trans = max(self.trans_std_per_m * path_m, FLOOR_M)
        rot = max(self.rot_std_per_rad * abs(turn_rad) + self.rot_std_per_m * path_m, FLOOR_RAD)
        return np.array([trans, trans, rot])
