"""`bslam import rosbag`: ROS 2 bags written here with rosbags' writer (MCAP and SQLite storage),
imported, read back with the mcap library; pixels decoded by OpenCV, poses by hand."""

from __future__ import annotations

import base64
import hashlib
import json
import math
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from click.testing import CliRunner
from importing import on, read_back

from replay.cli import cli

pytest.importorskip("rosbags.typesys")
from ros_messages import TS, T, camera_info, header, odometry
from rosbags.rosbag2 import StoragePlugin, Writer

W, H = 8, 6
K = [5.0, 0.0, 4.0, 0.0, 5.5, 3.0, 0.0, 0.0, 1.0]
D = [0.1, -0.01, 0.0, 0.0, 0.0]
LANDMARKS = {
    "landmarks": [{"name": "A", "color": "red"}, {"name": "B", "color": "green"}],
    "reference": ["A", "B"],
    "vision_error_deg": 2.5,
}


def _image(t_ns: int, bgr: np.ndarray, encoding: str) -> Any:
    if encoding == "png":
        ok, png = cv2.imencode(".png", bgr)
        assert ok
        return T["sensor_msgs/msg/CompressedImage"](
            header=header(t_ns, "camera"), format="png", data=png.ravel()
        )
    pixels = {
        "bgr8": bgr,
        "rgb8": bgr[:, :, ::-1],
        "mono8": bgr[:, :, 0],
        "rgba8": np.dstack([bgr[:, :, ::-1], np.full((H, W), 7, np.uint8)]),
    }[encoding]
    channels = 1 if pixels.ndim == 2 else pixels.shape[2]
    return T["sensor_msgs/msg/Image"](
        header=header(t_ns, "camera"), height=H, width=W, encoding=encoding, is_bigendian=0,
        step=W * channels, data=np.ascontiguousarray(pixels).ravel(),
    )  # fmt: skip


FRAMES_NS = [1_000_000_000, 1_100_000_001, 1_200_000_002]
POSES = [(1_050_000_000, 0.5, -0.25, math.pi / 2), (1_150_000_000, 1.0, 2.0, -3 * math.pi / 4)]


def _bag(tmp_path: Path, storage: StoragePlugin, encoding: str, frames: list[np.ndarray]) -> Path:
    path = tmp_path / "bag"
    image_type = "sensor_msgs/msg/CompressedImage" if encoding == "png" else "sensor_msgs/msg/Image"
    with Writer(path, version=9, storage_plugin=storage) as w:
        img = w.add_connection("/cam/image", image_type, typestore=TS)
        info = w.add_connection("/cam/info", "sensor_msgs/msg/CameraInfo", typestore=TS)
        odo = w.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=TS)
        chat = w.add_connection("/chatter", "std_msgs/msg/String", typestore=TS)
        w.write(
            chat,
            900_000_000,
            TS.serialize_cdr(T["std_msgs/msg/String"](data="hi"), "std_msgs/msg/String"),
        )
        w.write(
            info,
            950_000_000,
            TS.serialize_cdr(
                camera_info(950_000_000, "camera", W, H, K, D), "sensor_msgs/msg/CameraInfo"
            ),
        )
        stream = sorted(
            [(t, "img", i) for i, t in enumerate(FRAMES_NS)]
            + [(t, "odo", i) for i, (t, *_) in enumerate(POSES)]
        )
        for t, kind, i in stream:
            if kind == "img":
                # the bag receives each frame 3 ms after its header stamp
                w.write(
                    img, t + 3_000_000, TS.serialize_cdr(_image(t, frames[i], encoding), image_type)
                )
            else:
                w.write(
                    odo,
                    t + 3_000_000,
                    TS.serialize_cdr(odometry(*POSES[i]), "nav_msgs/msg/Odometry"),
                )
    (tmp_path / "landmarks.json").write_text(json.dumps(LANDMARKS))
    return path


def _import(tmp_path: Path, bag: Path, *extra: str) -> Any:
    args = ["import", "rosbag", str(bag), "--landmarks", str(tmp_path / "landmarks.json"),
            "-o", str(tmp_path / "out.mcap"), *extra]  # fmt: skip
    return CliRunner().invoke(cli, args)


def _frames(seed: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [rng.integers(0, 256, (H, W, 3), dtype=np.uint8) for _ in FRAMES_NS]


def _decoded(doc: dict[str, Any]) -> np.ndarray:
    assert doc["format"] == "png"
    data = np.frombuffer(base64.b64decode(doc["data"]), np.uint8)
    return cv2.imdecode(data, cv2.IMREAD_UNCHANGED)


@pytest.mark.parametrize("storage", [StoragePlugin.MCAP, StoragePlugin.SQLITE3])
def test_frames_calibration_and_odometry_come_through(
    tmp_path: Path, storage: StoragePlugin
) -> None:
    frames = _frames(1)
    bag = _bag(tmp_path, storage, "bgr8", frames)
    result = _import(tmp_path, bag)
    assert result.exit_code == 0, result.output
    session, messages = read_back(tmp_path / "out.mcap")
    cal = session["camera"]["calibration"]
    assert cal["model"] == "pinhole" and (cal["width"], cal["height"]) == (W, H)
    assert (cal["fx"], cal["fy"], cal["cx"], cal["cy"]) == (5.0, 5.5, 4.0, 3.0)
    assert cal["distortion"] == D and cal["distortion_model"] == "plumb_bob"
    assert [lm["name"] for lm in session["landmarks"]] == ["A", "B"]
    assert session["vision_error_deg"] == pytest.approx(2.5)
    images = on(messages, "/camera/panorama")
    assert [i["timestamp"]["sec"] * 10**9 + i["timestamp"]["nsec"] for i in images] == FRAMES_NS
    for doc, want in zip(images, frames, strict=True):
        assert np.array_equal(_decoded(doc), want)
    poses = on(messages, "/robot/odometry_pose")
    assert [(p["timestamp"]["sec"] * 10**9 + p["timestamp"]["nsec"]) for p in poses] == [
        t for t, *_ in POSES
    ]
    for p, (_, x, y, yaw) in zip(poses, POSES, strict=True):
        assert (p["x_m"], p["y_m"]) == (x, y)
        assert p["theta_rad"] == pytest.approx(yaw, abs=1e-12)
    # log time is the bag's receive time (3 ms after each stamp), in bag order
    log_times = [lt for t, lt, _, _ in messages]
    assert log_times == sorted(log_times) and log_times[0] == FRAMES_NS[0] + 3_000_000
    assert {t for t, *_ in messages} == {"/camera/panorama", "/robot/odometry_pose"}
    files = {f["name"]: f for f in session["provenance"]["files"]}
    assert "metadata.yaml" in files
    for path in bag.iterdir():
        assert files[path.name]["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.mark.parametrize("encoding", ["rgb8", "mono8", "rgba8", "png"])
def test_image_encodings_become_the_same_bgr_pixels(tmp_path: Path, encoding: str) -> None:
    frames = _frames(2)
    if encoding == "mono8":  # a grey frame: three equal channels
        frames = [np.repeat(f[:, :, :1], 3, axis=2) for f in frames]
    bag = _bag(tmp_path, StoragePlugin.MCAP, encoding, frames)
    result = _import(tmp_path, bag)
    assert result.exit_code == 0, result.output
    _, messages = read_back(tmp_path / "out.mcap")
    for doc, want in zip(on(messages, "/camera/panorama"), frames, strict=True):
        assert np.array_equal(_decoded(doc), want)


def test_topics_named_and_missing(tmp_path: Path) -> None:
    bag = _bag(tmp_path, StoragePlugin.MCAP, "bgr8", _frames(3))
    result = _import(tmp_path, bag, "--image-topic", "/cam/nope")
    assert result.exit_code == 1
    assert result.output.startswith("Error: the bag has no topic /cam/nope (it has /cam/image")
    result = _import(tmp_path, bag, "--odometry-topic", "/chatter")
    assert result.exit_code == 1
    assert "topic /chatter is std_msgs/msg/String, not nav_msgs/msg/Odometry" in result.output
    result = _import(tmp_path, tmp_path / "landmarks.json")
    assert result.exit_code == 1 and "is not a ROS 2 bag folder" in result.output
    assert not (tmp_path / "out.mcap").exists()
