"""The ROS 2 round trip: a simulated camera drive written as a ROS 2 bag (rosbags' writer:
``sensor_msgs/Image``, ``CameraInfo``, ``nav_msgs/Odometry``), imported with
``bslam import rosbag`` and processed, maps the same as the same drive written natively."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner

from recorder.sim.scenario import simulated_pinhole
from replay.cli import cli
from replay.drive_sim import (
    DriveCamera,
    band_codes,
    drive_frames,
    simulate_drive_log,
    simulated_drive,
)
from replay.records import FrameRecord, MethodConfig, MovementRecord, RunInfo
from replay.stages import run_log

pytest.importorskip("rosbags.typesys")
from ros_messages import TS, T, camera_info, header, odometry
from rosbags.rosbag2 import StoragePlugin, Writer

ARENA, DURATION_S, SEED, EPS_DEG = "square", 60.0, 5, 2.0


def _image(t_ns: int, bgr: np.ndarray) -> Any:
    h, w, _ = bgr.shape
    return T["sensor_msgs/msg/Image"](
        header=header(t_ns, "camera"), height=h, width=w, encoding="bgr8", is_bigendian=0,
        step=3 * w, data=np.ascontiguousarray(bgr).ravel(),
    )  # fmt: skip


def _camera_info(camera: DriveCamera) -> Any:
    c = camera.calibration.to_dict()
    k = [c["fx"], 0.0, c["cx"], 0.0, c["fy"], c["cy"], 0.0, 0.0, 1.0]
    return camera_info(0, "camera", c["width"], c["height"], k, [0.0] * 5)


def _write_bag(path: Path, camera: DriveCamera) -> None:
    """The drive's odometry and frames (the same renderer, the same seed) as a ROS 2 bag."""
    run = simulated_drive(ARENA, DURATION_S, SEED)
    frames = drive_frames(run, camera, math.radians(EPS_DEG), np.random.default_rng(SEED))
    stream: list[tuple[int, str, Any]] = [
        (int(t), "odo", p) for t, p in zip(run.t_ns, run.odometry.tolist(), strict=True)
    ]
    stream += [(t, "img", f.image_bgr) for t, f in frames]
    stream.sort(key=lambda s: s[0])
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        img = w.add_connection("/camera/image_raw", "sensor_msgs/msg/Image", typestore=TS)
        info = w.add_connection("/camera/camera_info", "sensor_msgs/msg/CameraInfo", typestore=TS)
        odo = w.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=TS)
        w.write(info, 0, TS.serialize_cdr(_camera_info(camera), "sensor_msgs/msg/CameraInfo"))
        for t, kind, data in stream:
            if kind == "img":
                w.write(img, t, TS.serialize_cdr(_image(t, data), "sensor_msgs/msg/Image"))
            else:
                msg = odometry(t, *data)
                w.write(odo, t, TS.serialize_cdr(msg, "nav_msgs/msg/Odometry"))


class Kept:
    """A sink that keeps the movement records."""

    wants_all_frames = False
    wants_images = False

    def __init__(self) -> None:
        self.movements: list[MovementRecord] = []

    def start(self, run: RunInfo) -> None:
        assert run.driving

    def frame(self, frame: FrameRecord) -> None:
        pass

    def movement(self, record: MovementRecord) -> None:
        self.movements.append(record)

    def association(self, record: object) -> None:
        raise AssertionError("no look-alike landmarks here")

    def finish(self) -> None:
        pass


@pytest.mark.slow
def test_a_ros2_bag_maps_the_same_as_the_native_log(tmp_path: Path) -> None:
    camera = DriveCamera(simulated_pinhole(320, 240, math.radians(60.0)))
    native = tmp_path / "native.mcap"
    simulate_drive_log(
        native, arena=ARENA, duration_s=DURATION_S, seed=SEED, vision_error_deg=EPS_DEG,
        camera=camera,
    )  # fmt: skip
    bag = tmp_path / "bag"
    _write_bag(bag, camera)
    names = [f"L{i + 1}" for i in range(8)]
    catalog = {
        "landmarks": [
            {"name": n, "bands": list(code)}
            for n, code in zip(names, band_codes(len(names)), strict=True)
        ],
        "reference": ["L1", "L2"],
        "vision_error_deg": EPS_DEG,
    }
    (tmp_path / "landmarks.json").write_text(json.dumps(catalog))
    imported = tmp_path / "imported.mcap"
    args = ["import", "rosbag", str(bag), "--landmarks", str(tmp_path / "landmarks.json"),
            "-o", str(imported)]  # fmt: skip
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    maps = []
    for path in (native, imported):
        kept = Kept()
        run_log(path, MethodConfig(), [kept])
        maps.append(kept)
    a, b = maps
    assert len(a.movements) == len(b.movements) > 50
    assert [m.timestamp_ns for m in a.movements] == [m.timestamp_ns for m in b.movements]
    final_a, final_b = a.movements[-1].estimates, b.movements[-1].estimates
    assert set(final_a) == set(final_b) == set(names) - {"L1", "L2"}
    # the inputs differ only by the quaternion's round-off (yaw, ~1e-16 rad); iSAM2's
    # relinearizations carry it to ~1e-9 FL (dev run: 1.2e-9 FL, 4 nm); 1e-6 FL is 3 um
    for name in final_a:
        np.testing.assert_allclose(final_a[name].mean_fl, final_b[name].mean_fl, rtol=0, atol=1e-6)
        np.testing.assert_allclose(
            final_a[name].cov_fl, final_b[name].cov_fl, rtol=1e-6, atol=1e-15
        )
    # both maps are maps of the arena: the keyframes' bearings agree one by one
    for ma, mb in zip(a.movements, b.movements, strict=True):
        assert set(ma.bearings_rad) == set(mb.bearings_rad)
