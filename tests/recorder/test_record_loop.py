"""The record loop against the fake Khepera on a real pty, in virtual time."""

from __future__ import annotations

import base64
import math
import os
import signal
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from data_schemas.calibration import UnwrappedCalibration
from data_schemas.codec import validate
from data_schemas.errors import CameraError
from data_schemas.mcap.read import LogMessage
from data_schemas.mcap.writer import LogWriter
from data_schemas.registry import TOPICS
from data_schemas.stamps import ns_from_stamp
from recorder.camera import CameraEndOfStream, OpenCVCamera
from recorder.clock import VirtualClock
from recorder.moves import Move, random_moves
from recorder.record import (
    CommandSink,
    Progress,
    RecordingInterrupted,
    RecordSettings,
    Rig,
    record_session,
    stop_on_signals,
)
from recorder.robot import KheperaRobot, RobotConfig, RobotDisconnected, RobotProtocolError
from recorder.sim.fake_khepera import FakeKhepera
from recorder.timebase import EpochClock
from tests.mcap_reader import LogReader
from tests.recorder.samples import make_session_doc

CAL = UnwrappedCalibration(32, 16)
TEN_HZ = RecordSettings(frame_rate_hz=10.0)


class _StillCamera:
    """Stand-in for a physical camera: the same noisy frame every time."""

    calibration = CAL

    def __init__(self) -> None:
        self.image = np.random.default_rng(0).integers(0, 256, (16, 32, 3), dtype=np.uint8)
        self.reads = 0

    def read(self) -> np.ndarray:
        self.reads += 1
        return self.image

    def close(self) -> None:
        pass


def _run(
    path: Path,
    moves: list[Move],
    *,
    camera: Any = None,
    fault: dict[str, Any] | None = None,
    progress: Any = None,
    settings: RecordSettings = TEN_HZ,
) -> tuple[FakeKhepera, Any]:
    base = VirtualClock()
    clock = EpochClock(base)
    fake = FakeKhepera(base, np.random.default_rng(1), initial_pose_world=(0.5, 0.3, 0.0))
    if fault:
        fake.inject(**fault)
    sink = CommandSink()
    camera = camera or _StillCamera()
    with fake.serve_pty() as server:
        config = RobotConfig(port=server.path, reply_timeout_s=0.2, retries=1)
        with KheperaRobot.open(config, clock, on_exchange=sink) as robot:
            robot.version()  # answered before the log exists: held by the sink
            rig = Rig(robot, sink, camera, clock, ground_truth=fake.pose_world)
            with LogWriter(path, make_session_doc(), clock=clock) as writer:
                result = record_session(rig, writer, moves, settings, progress=progress)
    return fake, result


def _read(path: Path) -> list[LogMessage]:
    with LogReader(path) as reader:  # finished (indexed) or this raises
        return list(reader.messages())


def _by_topic(msgs: list[LogMessage], topic_name: str) -> list[dict[str, Any]]:
    return [m.decode() for m in msgs if m.topic == topic_name]


def test_session_structure_and_every_message_validates(tmp_path: Path) -> None:
    path = tmp_path / "s.mcap"
    moves = [Move(math.radians(40), 0.08), Move(math.radians(-90), 0.05)]
    seen: list[Progress] = []
    fake, result = _run(path, moves, progress=seen.append)
    msgs = _read(path)
    for m in msgs:
        validate(TOPICS[m.topic].schema, m.decode(), what=m.topic)

    commands = _by_topic(msgs, "/robot/command")
    assert commands[0]["request"] == "B"  # the exchange before the log existed is kept
    assert [c["request"] for c in commands] == fake.requests  # every exchange is logged
    assert all(c["outcome"] == "ok" for c in commands)

    movements = _by_topic(msgs, "/robot/movement")
    assert [(m["index"], m["phase"]) for m in movements] == [
        (0, "start"),
        (0, "end"),
        (1, "start"),
        (1, "end"),
    ]
    frames = _by_topic(msgs, "/camera/panorama")
    truth = _by_topic(msgs, "/sim/ground_truth")
    frame_times = [ns_from_stamp(f["timestamp"]) for f in frames]
    assert [ns_from_stamp(t["timestamp"]) for t in truth] == frame_times  # truth at every frame
    for m in movements:
        assert ns_from_stamp(m["keyframe_timestamp"]) in frame_times
        assert m["turn_rad"] == moves[m["index"]].turn_rad

    # frames between the keyframes of a movement, at the configured rate (10 Hz)
    start, end = (ns_from_stamp(m["keyframe_timestamp"]) for m in movements[:2])
    between = [t for t in frame_times if start < t < end]
    drive_s = 0.08 / RobotConfig(port="x").move_speed_m_s
    assert len(between) >= int(drive_s * 10) - 1
    assert np.all(np.diff(between) >= 0.1e9 - 1)
    assert result.movements == 2 and result.frames == len(frames)
    assert [p.movements for p in seen] == [1, 2]

    # the keyframe poses are the fake robot's true poses, and the robot stopped at each
    odometry = _by_topic(msgs, "/robot/odometry")
    assert len(odometry) == 4
    assert odometry[1]["left_pulses"] == odometry[1]["right_pulses"] == round(0.08 / 0.08e-3)
    last = truth[-1]
    assert (last["x"], last["y"]) == pytest.approx(tuple(fake.pose_world())[:2])
    logs = [entry["message"] for entry in _by_topic(msgs, "/log")]
    assert logs[0].startswith("session started") and logs[-1].startswith("session finished")
    # after the turn, the start keyframe is at rest: D,0,0 precedes each keyframe
    assert fake.requests.count("D,0,0") == 4


def test_robot_disconnect_mid_session_keeps_the_data(tmp_path: Path) -> None:
    path = tmp_path / "s.mcap"
    moves = [Move(0.3, 0.05)] * 3
    with pytest.raises(RobotDisconnected):
        _run(path, moves, fault={"kind": "disconnect", "nth": 25})
    msgs = _read(path)  # finished, indexed
    for m in msgs:
        validate(TOPICS[m.topic].schema, m.decode(), what=m.topic)
    logs = _by_topic(msgs, "/log")
    assert logs[-1]["level"] == 4 and "fault after" in logs[-1]["message"]
    assert any(c["outcome"] == "disconnected" for c in _by_topic(msgs, "/robot/command"))
    assert len(_by_topic(msgs, "/camera/panorama")) > 0


def test_protocol_error_mid_session_stops_motors(tmp_path: Path) -> None:
    path = tmp_path / "s.mcap"
    with pytest.raises(RobotProtocolError, match="rejected the H command"):
        _run(path, [Move(0.3, 0.05)] * 2, fault={"kind": "protocol_error", "letter": "H"})
    msgs = _read(path)
    commands = _by_topic(msgs, "/robot/command")
    assert any(c["outcome"] == "protocol_error" for c in commands)
    assert commands[-1]["request"] == "D,0,0"  # motors stopped after the fault


def test_camera_end_of_stream_keeps_the_data(tmp_path: Path) -> None:
    rng = np.random.default_rng(5)
    for i in range(6):
        cv2.imwrite(str(tmp_path / f"f_{i:04d}.png"), rng.integers(0, 256, (16, 32, 3), np.uint8))
    camera = OpenCVCamera(str(tmp_path / "f_%04d.png"), CAL)
    path = tmp_path / "s.mcap"
    with pytest.raises(CameraEndOfStream):
        _run(path, [Move(0.2, 0.1)] * 3, camera=camera)
    msgs = _read(path)
    assert len(_by_topic(msgs, "/camera/panorama")) == 6  # every frame the camera gave
    assert "ended after 6 frames" in _by_topic(msgs, "/log")[-1]["message"]
    assert isinstance(CameraEndOfStream("x"), CameraError)


def test_sigint_stops_cleanly_at_a_safe_point(tmp_path: Path) -> None:
    path = tmp_path / "s.mcap"

    def interrupt(p: Progress) -> None:
        os.kill(os.getpid(), signal.SIGINT)  # a real signal, delivered to this process

    with stop_on_signals(), pytest.raises(RecordingInterrupted, match="SIGINT"):
        _run(path, [Move(0.2, 0.05)] * 5, progress=interrupt)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # restored
    msgs = _read(path)
    assert len(_by_topic(msgs, "/robot/movement")) == 2  # the first movement, complete
    assert "stopped by SIGINT" in _by_topic(msgs, "/log")[-1]["message"]
    assert _by_topic(msgs, "/robot/command")[-1]["request"] == "D,0,0"


def test_random_moves() -> None:
    moves = list(random_moves(np.random.default_rng(0), 200, (0.1, 0.3)))
    turns = np.array([m.turn_rad for m in moves])
    dists = np.array([m.distance_m for m in moves])
    assert len(moves) == 200
    assert turns.min() >= -math.pi and turns.max() < math.pi and turns.std() > 1.0
    assert dists.min() >= 0.1 and dists.max() <= 0.3
    fixed = list(random_moves(np.random.default_rng(0), 3, (0.2, 0.2), turn_rad=0.5))
    assert fixed == [Move(0.5, 0.2)] * 3
    endless: Iterator[Move] = random_moves(np.random.default_rng(0), None, (0.1, 0.2))
    assert len([next(endless) for _ in range(1000)]) == 1000


@pytest.mark.parametrize(
    "settings",
    [
        RecordSettings(frame_rate_hz=10.0, encoding="png", png_level=0),
        RecordSettings(frame_rate_hz=10.0, encoding="png", png_level=3),
        RecordSettings(frame_rate_hz=10.0, encoding="bgr8"),
    ],
)
def test_frames_are_stored_losslessly(tmp_path: Path, settings: RecordSettings) -> None:
    path = tmp_path / "s.mcap"
    camera = _StillCamera()
    _run(path, [Move(0.2, 0.05)], camera=camera, settings=settings)
    frames = [m for m in _read(path) if m.topic == "/camera/panorama"]
    assert len(frames) == camera.reads >= 2
    for m in frames:
        msg = m.decode()
        validate(m.schema, msg, what=m.topic)
        data = np.frombuffer(base64.b64decode(msg["data"]), np.uint8)
        if settings.encoding == "png":
            assert m.schema == "foxglove.CompressedImage" and msg["format"] == "png"
            image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
        else:
            assert m.schema == "foxglove.RawImage" and msg["step"] == 3 * msg["width"]
            image = data.reshape(msg["height"], msg["width"], 3)
        assert np.array_equal(image, camera.image)


def test_record_settings_are_checked() -> None:
    with pytest.raises(ValueError, match="frame rate must be > 0 Hz"):
        RecordSettings(frame_rate_hz=0.0)
    with pytest.raises(ValueError, match="encoding must be one of"):
        RecordSettings(encoding="jpeg")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"PNG level must be 0\.\.3"):
        RecordSettings(png_level=9)
    with pytest.raises(ValueError, match="poll period"):
        RecordSettings(poll_s=0.0)
