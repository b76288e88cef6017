"""A driving robot's camera log (frames on /camera/panorama and odometry poses, no movement
plan) through the driving estimator: bearings from the frames, a pinhole's field of view."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner
from importing import on, read_back

from recorder.sim.scenario import simulated_pinhole
from replay.cli import cli
from replay.drive_sim import DriveCamera, simulate_drive_log
from replay.records import FrameRecord, MethodConfig, MovementRecord, RunInfo
from replay.stages import run_log

FOV_DEG = 60.0
SHORT_S = 60.0
KEYFRAME_M, KEYFRAME_DEG = 0.3, 20.0  # the driving estimator's defaults


def pinhole_camera(width: int = 320, height: int = 240) -> DriveCamera:
    return DriveCamera(simulated_pinhole(width, height, math.radians(FOV_DEG)))


@pytest.fixture(scope="module")
def pinhole_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("frames") / "pinhole.mcap"
    simulate_drive_log(path, arena="square", duration_s=SHORT_S, seed=5, camera=pinhole_camera())
    return path


@dataclass
class Kept:
    """A sink that keeps what it is given (``wants_all_frames``: it asks for every frame)."""

    wants_all_frames: bool = False
    frames: list[FrameRecord] = field(default_factory=list)
    movements: list[MovementRecord] = field(default_factory=list)
    wants_images: bool = False

    def start(self, run: RunInfo) -> None:
        assert run.driving

    def frame(self, frame: FrameRecord) -> None:
        self.frames.append(frame)

    def movement(self, record: MovementRecord) -> None:
        self.movements.append(record)

    def association(self, record: object) -> None:
        raise AssertionError("no look-alike landmarks here")

    def finish(self) -> None:
        pass


def _keyframe_times_by_hand(odometry: list[dict[str, Any]]) -> list[int]:
    """Times (ns) of the keyframes of the rule along the odometry: path >= 0.3 m or turning
    >= 20 deg since the last one."""
    out, path, turn, last = [], 0.0, 0.0, None
    for o in odometry:
        p = (o["x_m"], o["y_m"], o["theta_rad"])
        t = int(o["timestamp"]["sec"]) * 10**9 + int(o["timestamp"]["nsec"])
        if last is None:
            out.append(t)
        else:
            path += math.dist(p[:2], last[:2])
            turn += abs(math.remainder(p[2] - last[2], 2 * math.pi))
            if path >= KEYFRAME_M or turn >= math.radians(KEYFRAME_DEG):
                out.append(t)
                path, turn = 0.0, 0.0
        last = p
    return out


@pytest.fixture(scope="module")
def kept(pinhole_log: Path) -> Kept:
    """The pinhole log's records (keyframes' frames only)."""
    sink = Kept()
    run_log(pinhole_log, MethodConfig(), [sink])
    return sink


def test_frames_and_odometry_map_through_the_driving_estimator(
    pinhole_log: Path, kept: Kept
) -> None:
    session, messages = read_back(pinhole_log)
    assert session["camera"]["calibration"]["model"] == "pinhole"
    assert not on(messages, "/robot/movement") and not on(messages, "/sensor/bearings")
    n_frames = len(on(messages, "/camera/panorama"))
    keyframes = _keyframe_times_by_hand(on(messages, "/robot/odometry_pose"))
    assert len(kept.movements) == len(keyframes)
    # only keyframes' frames are decoded: the first frame after each keyframe's odometry
    frame_times = sorted(
        int(d["timestamp"]["sec"]) * 10**9 + int(d["timestamp"]["nsec"])
        for d in on(messages, "/camera/panorama")
    )
    firsts = sorted({f for t in keyframes if (f := next((f for f in frame_times if f >= t), None))})
    assert [f.timestamp_ns for f in kept.frames] == firsts
    assert len(firsts) < n_frames / 2
    assert all(f.keyframe is not None for f in kept.frames)
    # the map (FL: L1 at 0, L2 at 1) against the session's truth after the best similarity,
    # fitted here with complex numbers: truth = a * map + b by least squares
    truth = {t["name"]: complex(t["x_m"], t["y_m"]) for t in session["truth"]["landmarks"]}
    final = kept.movements[-1].estimates
    assert set(final) == set(truth) - {"L1", "L2"}  # every landmark (besides the pair)
    est = {"L1": 0j, "L2": 1 + 0j, **{n: complex(*e.mean_fl) for n, e in final.items()}}
    names = sorted(est)
    z = np.array([est[n] for n in names])
    w = np.array([truth[n] for n in names])
    (a, b), *_ = np.linalg.lstsq(np.column_stack([z, np.ones_like(z)]), w, rcond=None)
    errors_m = np.abs(a * z + b - w)
    assert errors_m.mean() < 0.12 and errors_m.max() < 0.25, errors_m


def test_a_sink_wanting_every_frame_changes_no_bearing_of_the_map(
    pinhole_log: Path, kept: Kept
) -> None:
    few, every = kept, Kept(wants_all_frames=True)
    run_log(pinhole_log, MethodConfig(), [every])
    _, messages = read_back(pinhole_log)
    assert len(every.frames) == len(on(messages, "/camera/panorama"))
    assert [f.timestamp_ns for f in every.frames if f.keyframe is not None] == [
        f.timestamp_ns for f in few.frames
    ]
    a, b = few.movements[-1].estimates, every.movements[-1].estimates
    assert set(a) == set(b)
    for name in a:
        assert np.array_equal(a[name].mean_fl, b[name].mean_fl)


def test_a_mapped_landmark_behind_the_pinhole_is_not_visible_not_missed(
    pinhole_log: Path, kept: Kept
) -> None:
    session, messages = read_back(pinhole_log)
    truth = {t["name"]: (t["x_m"], t["y_m"]) for t in session["truth"]["landmarks"]}
    poses = {
        int(d["timestamp"]["sec"]) * 10**9 + int(d["timestamp"]["nsec"]): d
        for d in on(messages, "/sim/ground_truth")
    }
    final = set(kept.movements[-1].estimates)
    checked = 0
    for record in kept.movements:
        pose = poses[record.timestamp_ns]
        for name in final - set(record.bearings_rad):
            x, y = truth[name]
            off = math.remainder(
                math.atan2(y - pose["y"], x - pose["x"]) - pose["heading"], math.tau
            )
            # well outside (by 10 deg) or well inside the 60-degree view, by the true pose
            if abs(off) > math.radians(FOV_DEG / 2 + 10) and name in set(record.estimates):
                assert record.not_visible.get(name) == "outside the camera's field of view"
                checked += 1
        for name in record.not_visible:
            assert name not in record.bearings_rad
    assert checked > 10


def test_process_cli_maps_a_camera_drive(pinhole_log: Path, tmp_path: Path) -> None:
    summary = tmp_path / "s.json"
    result = CliRunner().invoke(cli, ["process", str(pinhole_log), "--summary", str(summary)])
    assert result.exit_code == 0, result.output
    doc = json.loads(summary.read_text())
    assert doc["method"]["estimator"] == "driving"
    assert len(doc["landmarks"]) == 6
