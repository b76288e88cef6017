"""ROS 2 messages for the bags the tests write with rosbags' writer (no ROS install).

Import it after ``pytest.importorskip("rosbags.typesys")``: it needs rosbags (the ``ros`` extra).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from rosbags.typesys import Stores, get_typestore

#: ROS 2 Humble's type store (serializes messages) and its message types.
TS = get_typestore(Stores.ROS2_HUMBLE)
T = TS.types


def header(t_ns: int, frame: str) -> Any:
    """``std_msgs/Header`` stamped ``t_ns`` (ns) in ``frame``."""
    stamp = T["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9)
    return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)


def camera_info(
    t_ns: int, frame: str, width: int, height: int, k: Sequence[float], d: Sequence[float]
) -> Any:
    """``sensor_msgs/CameraInfo``: plumb_bob model, K (row-major 3 x 3) and D, no rectification."""
    roi = T["sensor_msgs/msg/RegionOfInterest"](
        x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
    )
    return T["sensor_msgs/msg/CameraInfo"](
        header=header(t_ns, frame), height=height, width=width, distortion_model="plumb_bob",
        d=np.array(d, dtype=np.float64), k=np.array(k, dtype=np.float64), r=np.eye(3).ravel(),
        p=np.zeros(12), binning_x=0, binning_y=0, roi=roi,
    )  # fmt: skip


def odometry(t_ns: int, x: float, y: float, yaw: float) -> Any:
    """``nav_msgs/Odometry`` in ``odom``: pose (x, y in m, yaw in rad as a quaternion), no twist."""
    point = T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0)
    q = T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))
    pose = T["geometry_msgs/msg/PoseWithCovariance"](
        pose=T["geometry_msgs/msg/Pose"](position=point, orientation=q), covariance=np.zeros(36)
    )
    zero = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
    twist = T["geometry_msgs/msg/TwistWithCovariance"](
        twist=T["geometry_msgs/msg/Twist"](linear=zero, angular=zero), covariance=np.zeros(36)
    )
    return T["nav_msgs/msg/Odometry"](
        header=header(t_ns, "odom"), child_frame_id="base_link", pose=pose, twist=twist
    )
