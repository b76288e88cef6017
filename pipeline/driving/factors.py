"""GTSAM factors of a driving robot's graph (metres, the frame of the first keyframe's gauge).

One ``Pose2`` per keyframe (key ``x(k)``), one ``Point2`` per landmark (key ``l(j)``, ``j`` its
catalog index: :func:`pipeline.joint.graph.landmark_key`). Odometry links consecutive
keyframes (``BetweenFactorPose2``, wheel-model noise). A bearing taken at a keyframe is a
``BearingFactor2D``; one taken between keyframes hangs on the keyframe before it through the
odometry increment ``offset`` from that keyframe to the sensor (:func:`offset_bearing_factor`).
"""

from __future__ import annotations

import math

import gtsam
import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad
from pipeline.joint.graph import bearing_factor

#: Std of the gauge prior on the first keyframe: position (m) and heading (rad).
GAUGE_SIGMA = 1e-6


def keyframe_key(k: int) -> int:
    """Key of keyframe ``k``."""
    return int(gtsam.symbol("x", k))


def odometry_factor(
    k0: int, k1: int, delta: NDArray[np.float64], sigmas: NDArray[np.float64]
) -> gtsam.NonlinearFactor:
    """Keyframe ``k1`` is keyframe ``k0`` moved by the odometry increment ``delta`` (3,) (body
    frame of ``k0``: m, m, rad) with stds ``sigmas`` (3,)."""
    noise = gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sigmas, np.float64))
    return gtsam.BetweenFactorPose2(
        keyframe_key(k0), keyframe_key(k1), gtsam.Pose2(*map(float, delta)), noise
    )


def gauge_factor(pose: NDArray[np.float64]) -> gtsam.NonlinearFactor:
    """Keyframe 0 held at ``pose`` (3,): the map's origin and heading."""
    noise = gtsam.noiseModel.Isotropic.Sigma(3, GAUGE_SIGMA)
    return gtsam.PriorFactorPose2(keyframe_key(0), gtsam.Pose2(*map(float, pose)), noise)


def offset_bearing_factor(
    pose: int,
    landmark: int,
    bearing_rad: float,
    offset: NDArray[np.float64],
    noise: gtsam.noiseModel.Base,
) -> gtsam.NonlinearFactor:
    """Bearing of a landmark seen by a sensor at pose ``pose`` moved by ``offset`` (3,) (body
    frame: m, m, rad): a ``BearingFactor2D`` when the offset is zero.

    The error is ``wrap(predicted - measured)``; its Jacobians are in ``Pose2``'s tangent space
    (body-frame translation, then rotation) and in the point's coordinates.
    """
    if not np.any(offset):
        return bearing_factor(pose, landmark, bearing_rad, noise)
    ox, oy, oth = (float(v) for v in offset)

    def error(
        this: gtsam.CustomFactor, values: gtsam.Values, jac: list[NDArray[np.float64]] | None
    ) -> NDArray[np.float64]:
        p = values.atPose2(this.keys()[0])
        pt = values.atPoint2(this.keys()[1])
        c, s = math.cos(p.theta()), math.sin(p.theta())
        sx = p.x() + c * ox - s * oy
        sy = p.y() + s * ox + c * oy
        dx, dy = float(pt[0]) - sx, float(pt[1]) - sy
        pred = math.atan2(dy, dx) - p.theta() - oth
        if jac is not None:
            r2 = max(dx * dx + dy * dy, 1e-18)
            gx, gy = dy / r2, -dx / r2  # d pred / d sensor position (world)
            # sensor position: t + R(theta) (delta + offset); heading theta + dtheta
            jx, jy = gx * c + gy * s, -gx * s + gy * c
            jth = jx * -oy + jy * ox - 1.0
            jac[0] = np.array([[jx, jy, jth]])
            jac[1] = np.array([[-gx, -gy]])
        return np.array([float(wrap_rad(pred - bearing_rad))])

    return gtsam.CustomFactor(noise, [pose, landmark], error)


def fixed_sensor_bearing_factor(
    landmark: int,
    sensor_pose: NDArray[np.float64],
    bearing_rad: float,
    noise: gtsam.noiseModel.Base,
) -> gtsam.NonlinearFactor:
    """Bearing of a landmark seen from a sensor held at ``sensor_pose`` (3,) (m, m, rad, map
    frame): a bearing of a keyframe that has left the graph, on the landmark alone.

    The error is ``wrap(predicted - measured)``; its Jacobian is in the point's coordinates.
    """
    sx, sy, sth = (float(v) for v in sensor_pose)

    def error(
        this: gtsam.CustomFactor, values: gtsam.Values, jac: list[NDArray[np.float64]] | None
    ) -> NDArray[np.float64]:
        pt = values.atPoint2(this.keys()[0])
        dx, dy = float(pt[0]) - sx, float(pt[1]) - sy
        if jac is not None:
            r2 = max(dx * dx + dy * dy, 1e-18)
            jac[0] = np.array([[-dy / r2, dx / r2]])
        return np.array([float(wrap_rad(math.atan2(dy, dx) - sth - bearing_rad))])

    return gtsam.CustomFactor(noise, [landmark], error)
