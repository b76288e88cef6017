"""The map in Foxglove's well-known schemas, for the 3D panel (derived logs, :mod:`.derived`).

Foxglove's 3D panel draws only its own schemas; these builders turn a movement's results into
them. Everything is in the landmark frame ``fl`` (:data:`FL_FRAME`: L1 = (0, 0), L2 = (1, 0),
unit |L1 L2|, z = 0), which the panel shows as metres. Schemas (``data_schemas/foxglove/``):

================================ ==========================================================
``foxglove.SceneUpdate``         the map: a sphere, the 80% credible ellipse and a label per
                                 landmark (every entity is replaced at each movement)
``foxglove.PosesInFrame``        the keyframe poses of one movement (at O1 and O2, heading
                                 O1 -> O2), and the trajectory: every keyframe pose so far
``foxglove.FrameTransform``      ``fl`` -> ``robot`` (:data:`ROBOT_FRAME`): the robot's pose at
                                 a keyframe, so the panel can follow the robot
``foxglove.PointCloud``          the belief's particles (fields ``x``, ``y``, ``z``,
                                 ``landmark``: the landmark's index in the map's order)
================================ ==========================================================

A frame transform cannot scale, so a metric frame is not a child of ``fl``: the map is in units of
|L1 L2| (the summary's ``map_unit_m`` gives it in metres, when known).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from data_schemas.stamps import Stamp
from replay.records import EstimateRecord

#: The landmark frame's name in Foxglove messages.
FL_FRAME = "fl"
#: The robot's frame (its pose at a keyframe, ``fl`` -> ``robot``).
ROBOT_FRAME = "robot"
#: Sphere diameter of a landmark, FL units.
LANDMARK_SIZE_FL = 0.04
#: ``foxglove.LineType`` LINE_STRIP, ``foxglove.SceneEntityDeletionType`` ALL,
#: ``foxglove.NumericType`` FLOAT32 (the schemas' enum values).
LINE_STRIP = 0
DELETE_ALL = 1
FLOAT32 = 7
#: Point cloud fields, each float32, in this order.
CLOUD_FIELDS = ("x", "y", "z", "landmark")

Pose2 = tuple[float, float, float]
"""A pose in FL: x, y (FL units) and heading (rad, counter-clockwise from FL's x axis)."""


def _vector(x: float, y: float, z: float = 0.0) -> dict[str, float]:
    return {"x": float(x), "y": float(y), "z": float(z)}


def yaw_quaternion(yaw_rad: float) -> dict[str, float]:
    """The quaternion of a rotation by ``yaw_rad`` about z (``foxglove.Quaternion``)."""
    half = 0.5 * yaw_rad
    return {"x": 0.0, "y": 0.0, "z": math.sin(half), "w": math.cos(half)}


def _pose(x: float, y: float, yaw_rad: float = 0.0) -> dict[str, Any]:
    return {"position": _vector(x, y), "orientation": yaw_quaternion(yaw_rad)}


def _color(rgb: tuple[int, int, int], alpha: float = 1.0) -> dict[str, float]:
    r, g, b = rgb
    return {"r": r / 255.0, "g": g / 255.0, "b": b / 255.0, "a": alpha}


def keyframe_poses(o1_fl: NDArray[np.floating], o2_fl: NDArray[np.floating]) -> list[Pose2]:
    """A straight movement's two keyframe poses in FL: at O1 and O2, both heading O1 -> O2.

    Parameters
    ----------
    o1_fl, o2_fl : (n, 2) or (2,) arrays
        Observation points in FL (particles or a point); their means are the positions.
    """
    p1 = np.asarray(o1_fl, np.float64).reshape(-1, 2).mean(axis=0)
    p2 = np.asarray(o2_fl, np.float64).reshape(-1, 2).mean(axis=0)
    heading = math.atan2(p2[1] - p1[1], p2[0] - p1[0])
    return [(float(p1[0]), float(p1[1]), heading), (float(p2[0]), float(p2[1]), heading)]


def poses_in_frame(stamp: Stamp, poses: Sequence[Pose2]) -> dict[str, Any]:
    """A ``foxglove.PosesInFrame`` of poses in FL."""
    return {
        "timestamp": stamp,
        "frame_id": FL_FRAME,
        "poses": [_pose(x, y, yaw) for x, y, yaw in poses],
    }


def robot_transform(stamp: Stamp, pose: Pose2) -> dict[str, Any]:
    """A ``foxglove.FrameTransform`` ``fl`` -> ``robot``: the robot at ``pose`` (FL)."""
    x, y, yaw = pose
    return {
        "timestamp": stamp,
        "parent_frame_id": FL_FRAME,
        "child_frame_id": ROBOT_FRAME,
        "translation": _vector(x, y),
        "rotation": yaw_quaternion(yaw),
    }


def _landmark_entity(
    stamp: Stamp,
    name: str,
    estimate: EstimateRecord,
    rgb: tuple[int, int, int],
    ellipse_rgb: tuple[int, int, int],
) -> dict[str, Any]:
    x, y = (float(v) for v in estimate.mean_fl)
    outline = np.asarray(estimate.ellipse80_fl, np.float64).reshape(-1, 2)
    size = LANDMARK_SIZE_FL
    return {
        "timestamp": stamp,
        "frame_id": FL_FRAME,
        "id": f"landmark/{name}",
        "lifetime": {"sec": 0, "nsec": 0},
        "frame_locked": False,
        "metadata": [
            {"key": "name", "value": name},
            {"key": "mean_fl", "value": f"{x:.6g}, {y:.6g}"},
        ],
        "arrows": [],
        "cubes": [],
        "spheres": [{"pose": _pose(x, y), "size": _vector(size, size, size), "color": _color(rgb)}],
        "cylinders": [],
        "lines": [
            {
                "type": LINE_STRIP,
                "pose": _pose(0.0, 0.0),
                "thickness": 2.0,
                "scale_invariant": True,
                "points": [_vector(px, py) for px, py in outline],
                "color": _color(ellipse_rgb),
                "colors": [],
                "indices": [],
            }
        ],
        "triangles": [],
        "texts": [
            {
                "pose": _pose(x, y + size),
                "billboard": True,
                "font_size": 14.0,
                "scale_invariant": True,
                "color": _color(rgb),
                "text": name,
            }
        ],
        "models": [],
    }


def scene_update(
    stamp: Stamp,
    estimates: Mapping[str, EstimateRecord],
    rgb: Mapping[str, tuple[int, int, int]],
    ellipse_rgb: tuple[int, int, int],
) -> dict[str, Any]:
    """A ``foxglove.SceneUpdate`` of the map: the old map deleted, one entity per landmark.

    Parameters
    ----------
    estimates : dict name -> EstimateRecord
        The map (FL).
    rgb : dict name -> (r, g, b)
        Each landmark's colour (grey if absent); ``ellipse_rgb`` colours the 80% ellipses.
    """
    return {
        "deletions": [{"timestamp": stamp, "type": DELETE_ALL, "id": ""}],
        "entities": [
            _landmark_entity(stamp, n, e, rgb.get(n, (200, 200, 200)), ellipse_rgb)
            for n, e in estimates.items()
        ],
    }


def point_cloud(stamp: Stamp, particles_fl: Mapping[str, NDArray[np.floating]]) -> dict[str, Any]:
    """A ``foxglove.PointCloud`` of every landmark's particles (n, 2) in FL.

    Each point is four little-endian float32: x, y, z = 0 and ``landmark``, the index of its
    landmark in ``particles_fl``'s order. ``data`` is bytes (the log writer encodes it).
    """
    blocks = []
    for k, p in enumerate(particles_fl.values()):
        xy = np.asarray(p, np.float64).reshape(-1, 2)
        block = np.zeros((len(xy), len(CLOUD_FIELDS)), "<f4")
        block[:, :2] = xy
        block[:, 3] = k
        blocks.append(block)
    points = np.concatenate(blocks) if blocks else np.zeros((0, len(CLOUD_FIELDS)), "<f4")
    width = np.dtype("<f4").itemsize
    return {
        "timestamp": stamp,
        "frame_id": FL_FRAME,
        "pose": _pose(0.0, 0.0),
        "point_stride": width * len(CLOUD_FIELDS),
        "fields": [
            {"name": name, "offset": width * i, "type": FLOAT32}
            for i, name in enumerate(CLOUD_FIELDS)
        ],
        "data": points.tobytes(),
    }
