"""Wheel velocities integrated into odometry poses (unicycle model, exact over each interval).

A velocity row ``(t_i, v_i, omega_i)`` holds from ``t_i`` until the next row's time. Over an
interval ``dt`` with constant ``v`` and ``omega`` the robot drives an arc::

    theta' = theta + omega dt
    x' = x + v (sin theta' - sin theta) / omega        (x + v dt cos theta if omega = 0)
    y' = y - v (cos theta' - cos theta) / omega        (y + v dt sin theta if omega = 0)

The first pose is ``(0, 0, 0)`` at the first row's time: the odometry frame's origin.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from data_schemas.angles import wrap_rad

#: below this |omega dt| (rad) the arc is taken as straight (its error ~ (omega dt)^2 / 6).
_STRAIGHT_RAD = 1e-9


def integrate_velocities(
    t_ns: Sequence[int], v_mps: Sequence[float], omega_radps: Sequence[float]
) -> list[tuple[float, float, float]]:
    """Odometry poses ``(x_m, y_m, theta_rad)`` at each row's time, odometry frame.

    Parameters
    ----------
    t_ns : sequence of int, (N,)
        Strictly increasing row times, ns.
    v_mps, omega_radps : sequence of float, (N,)
        Forward speed (m/s) and turn rate (rad/s, CCW) from each row's time to the next.

    Returns
    -------
    list of (x_m, y_m, theta_rad), (N,)
        ``theta_rad`` wrapped to [-pi, pi).
    """
    x = y = theta = 0.0
    poses = []
    for i, t in enumerate(t_ns):
        if i:
            dt = (t - t_ns[i - 1]) * 1e-9
            v, w = v_mps[i - 1], omega_radps[i - 1]
            turn = w * dt
            if abs(turn) < _STRAIGHT_RAD:
                x += v * dt * math.cos(theta)
                y += v * dt * math.sin(theta)
            else:
                x += v / w * (math.sin(theta + turn) - math.sin(theta))
                y -= v / w * (math.cos(theta + turn) - math.cos(theta))
            theta = wrap_rad(theta + turn)
        poses.append((x, y, theta))
    return poses
