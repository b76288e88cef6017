"""A ROS 2 bag (MCAP or SQLite storage) into a bearing-slam log, with no ROS install.

Read with ``rosbags`` (the ``ros`` extra): pure Python, it reads both rosbag2 storage formats
(``.mcap`` and ``.db3``) and deserializes CDR with its own type store (message definitions
embedded in the bag, else ROS 2 Humble's standard ones), so neither ROS nor compiled message
packages are needed. (``mcap-ros2-support`` reads MCAP storage only, not ``.db3``.)

Topics (each found by its type when the bag has exactly one of it, or given):

* ``sensor_msgs/msg/Image`` (``bgr8``, ``rgb8``, ``bgra8``, ``rgba8``, ``mono8``) or
  ``sensor_msgs/msg/CompressedImage`` (any format OpenCV decodes): ``/camera/panorama``, stored
  lossless as PNG (greyscale frames as three equal channels);
* ``sensor_msgs/msg/CameraInfo``: the session's pinhole calibration (its first message), unless
  a calibration file is given;
* ``nav_msgs/msg/Odometry``: ``/robot/odometry_pose`` (x, y and the yaw of the orientation).

A message's sensor time is its header stamp; the log keeps the bag's order and times
(``log_time``). The landmark catalog (colours or bands, reference pair, eps) is a landmark file
as ``bslam record`` reads it.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from data_schemas.calibration import Calibration, pinhole_from_camera_info
from data_schemas.registry import CAMERA_TOPIC
from data_schemas.stamps import NS_PER_S
from recorder.frames import frame_message
from recorder.session import landmark_entry, load_calibration_file, load_landmark_file
from replay.extras import require
from replay.importers.source import (
    ImportedLog,
    ImportSourceError,
    Message,
    SourceFile,
    imported_session,
    odometry_pose,
    require_files,
)

#: Raised whenever the same bag would import differently.
ROSBAG_IMPORTER_VERSION = 1
IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
CAMERA_INFO_TYPE = "sensor_msgs/msg/CameraInfo"
ODOMETRY_TYPE = "nav_msgs/msg/Odometry"
#: Raw image encodings read, and how to make BGR of them (OpenCV conversion codes by name).
RAW_ENCODINGS = {"bgr8": 3, "rgb8": 3, "bgra8": 4, "rgba8": 4, "mono8": 1}
#: PNG level of the imported frames (recorder.png: 1 stores about half the raw size).
PNG_LEVEL = 1


@dataclass(frozen=True)
class RosbagImporter:
    """One ROS 2 bag folder (``metadata.yaml`` and its storage files), module docstring."""

    bag: Path
    landmarks: Path
    image_topic: str | None = None
    camera_info_topic: str | None = None
    odometry_topic: str | None = None
    calibration: Path | None = None

    @property
    def folder(self) -> Path:
        """The bag's folder (a storage file given: the folder holding it)."""
        return self.bag if self.bag.is_dir() or not self.bag.suffix else self.bag.parent

    @property
    def inputs(self) -> Sequence[SourceFile]:
        """The bag's files (metadata and storage), the landmark file and any calibration."""
        bag_files = (
            sorted(p for p in self.folder.glob("*") if p.is_file()) if self.folder.is_dir() else []
        )
        files = [SourceFile("bag", p) for p in bag_files]
        files.append(SourceFile("landmarks", self.landmarks))
        if self.calibration is not None:
            files.append(SourceFile("calibration", self.calibration))
        return files

    def read(self) -> ImportedLog:
        """Open the bag, find the topics, read the calibration; frames are read as written."""
        rosbags = require("rosbags.highlevel", extra="ros", feature="bslam import rosbag")
        typesys = require("rosbags.typesys", extra="ros", feature="bslam import rosbag")
        if not (self.folder / "metadata.yaml").is_file():
            raise ImportSourceError(
                f"{self.bag} is not a ROS 2 bag folder (no metadata.yaml beside its storage)"
            )
        require_files(self.inputs)
        catalog = load_landmark_file(self.landmarks)
        reader = rosbags.AnyReader(
            [self.folder], default_typestore=typesys.get_typestore(typesys.Stores.ROS2_HUMBLE)
        )
        try:
            reader.open()
        except Exception as exc:  # rosbags' reader errors have no common base
            raise ImportSourceError(f"cannot read ROS 2 bag {self.folder}: {exc}") from None
        try:
            return self._read(reader, catalog)
        except BaseException:
            reader.close()
            raise

    def _read(self, reader: Any, catalog: Any) -> ImportedLog:
        by_topic = {c.topic: c for c in reader.connections}
        image = _topic(by_topic, self.image_topic, IMAGE_TYPES, "image", "--image-topic")
        info = None
        if self.calibration is None:
            info = _topic(by_topic, self.camera_info_topic, (CAMERA_INFO_TYPE,), "camera info",
                          "--camera-info-topic or --calibration")  # fmt: skip
        odom = _topic(
            by_topic, self.odometry_topic, (ODOMETRY_TYPE,), "odometry", "--odometry-topic"
        )
        calibration = self._calibration(reader, info)
        n_frames, n_odom = image.msgcount, odom.msgcount
        span_s = max(reader.duration, 1) / NS_PER_S
        camera = {
            "source": f"rosbag {self.folder.name} {image.topic}",
            "calibration": calibration.to_dict(),
            "encoding": "png",
            "frame_rate_hz": round(max(n_frames - 1, 1) / span_s, 6),
        }
        options = {
            "image_topic": image.topic,
            "camera_info_topic": None if info is None else info.topic,
            "odometry_topic": odom.topic,
        }
        doc = imported_session(
            kind="rosbag",
            importer_version=ROSBAG_IMPORTER_VERSION,
            files=self.inputs,
            options=options,
            landmarks=[landmark_entry(lm) for lm in catalog.landmarks],
            reference=catalog.reference,
            vision_error_deg=math.degrees(catalog.vision_error_rad),
            range_m=catalog.range_m,
            camera=camera,
        )
        notes = [f"{n_frames} frames from {image.topic}, {n_odom} poses from {odom.topic}"]
        return ImportedLog(
            doc, _messages(reader, image, odom, calibration), n_frames + n_odom, notes
        )

    def _calibration(self, reader: Any, info: Any) -> Calibration:
        if self.calibration is not None:
            return load_calibration_file(self.calibration)
        for connection, _, raw in reader.messages(connections=[info]):
            msg = reader.deserialize(raw, connection.msgtype)
            return pinhole_from_camera_info(
                {
                    "width": msg.width,
                    "height": msg.height,
                    "k": [float(v) for v in msg.k],
                    "d": [float(v) for v in msg.d],
                    "distortion_model": msg.distortion_model,
                }
            )
        raise ImportSourceError(f"camera info topic {info.topic} has no message")


def _topic(
    by_topic: dict[str, Any], given: str | None, types: Sequence[str], what: str, option: str
) -> Any:
    """The connection of ``given``, or the one topic of ``types`` (raise naming the option)."""
    if given is not None:
        connection = by_topic.get(given)
        if connection is None:
            raise ImportSourceError(
                f"the bag has no topic {given} (it has {', '.join(sorted(by_topic))})"
            )
        if connection.msgtype not in types:
            raise ImportSourceError(
                f"topic {given} is {connection.msgtype}, not {' or '.join(types)}"
            )
        return connection
    found = [c for c in by_topic.values() if c.msgtype in types]
    if len(found) != 1:
        have = ", ".join(f"{c.topic} ({c.msgtype})" for c in by_topic.values()) or "no topics"
        count = "no" if not found else "several"
        raise ImportSourceError(f"the bag has {count} {what} topics ({have}); give {option}")
    return found[0]


def _stamp_ns(header: Any, fallback_ns: int) -> int:
    """A header's stamp in ns (the bag's time if the stamp is zero)."""
    t_ns = int(header.stamp.sec) * NS_PER_S + int(header.stamp.nanosec)
    return t_ns if t_ns > 0 else fallback_ns


def _messages(reader: Any, image: Any, odom: Any, calibration: Calibration) -> Iterator[Message]:
    """Frames and poses in bag order; closes the reader when done."""
    try:
        for connection, bag_ns, raw in reader.messages(connections=[image, odom]):
            msg = reader.deserialize(raw, connection.msgtype)
            t_ns = _stamp_ns(msg.header, bag_ns)
            if connection is odom:
                q = msg.pose.pose.orientation
                yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
                p = msg.pose.pose.position
                pose = odometry_pose(t_ns, float(p.x), float(p.y), yaw)
                yield Message(bag_ns, pose.topic, pose.doc)
                continue
            bgr = _bgr(msg, connection.msgtype, connection.topic)
            if bgr.shape[1] != calibration.width or bgr.shape[0] != calibration.height:
                raise ImportSourceError(
                    f"{connection.topic}: a {bgr.shape[1]} x {bgr.shape[0]} frame, but the "
                    f"calibration is {calibration.width} x {calibration.height}"
                )
            frame = frame_message(bgr, t_ns, encoding="png", png_level=PNG_LEVEL)
            yield Message(bag_ns, CAMERA_TOPIC, frame)
    finally:
        reader.close()


def _bgr(msg: Any, msgtype: str, topic: str) -> NDArray[np.uint8]:
    """A BGR uint8 (H, W, 3) image of an Image or CompressedImage message."""
    import cv2

    if msgtype.endswith("CompressedImage"):
        data = np.frombuffer(bytes(msg.data), np.uint8)
        decoded = cv2.imdecode(data, cv2.IMREAD_COLOR)
        if decoded is None:
            raise ImportSourceError(f"{topic}: a {msg.format!r} frame OpenCV cannot decode")
        return np.ascontiguousarray(decoded, np.uint8)
    channels = RAW_ENCODINGS.get(msg.encoding)
    if channels is None:
        raise ImportSourceError(
            f"{topic}: image encoding {msg.encoding!r} is not read; use one of "
            + ", ".join(RAW_ENCODINGS)
        )
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    data = np.asarray(msg.data, np.uint8)
    if step < width * channels or data.size < step * height:
        raise ImportSourceError(
            f"{topic}: image data too short for {width} x {height} {msg.encoding}"
        )
    pixels = (
        data[: step * height]
        .reshape(height, step)[:, : width * channels]
        .reshape(height, width, channels)
    )
    convert = {
        "rgb8": cv2.COLOR_RGB2BGR,
        "bgra8": cv2.COLOR_BGRA2BGR,
        "rgba8": cv2.COLOR_RGBA2BGR,
        "mono8": cv2.COLOR_GRAY2BGR,
    }.get(msg.encoding)
    bgr = pixels if convert is None else cv2.cvtColor(pixels, convert)
    return np.ascontiguousarray(bgr, np.uint8)
