"""A session started from Python: record_robot_session against the fake Khepera on a pty."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import cv2
import numpy as np
import pytest

from data_schemas.errors import CalibrationError
from recorder.clock import SystemClock
from recorder.record import RecordSettings
from recorder.sim.fake_khepera import FakeKhepera
from recorder.start import RobotSessionSpec, record_robot_session
from tests.mcap_reader import LogReader

H, W = 24, 64


def _spec(tmp_path: Path, port: str, **changes: object) -> RobotSessionSpec:
    rng = np.random.default_rng(0)
    distinct = [tmp_path / f"distinct_{k}.png" for k in range(4)]
    for path in distinct:
        cv2.imwrite(str(path), rng.integers(0, 256, (H, W, 3), np.uint8))
    for i in range(300):  # more frames than the session reads (hard links: cheap)
        os.link(distinct[i % 4], tmp_path / f"f_{i:04d}.png")
    (tmp_path / "cal.json").write_text(json.dumps({"model": "unwrapped", "width": W, "height": H}))
    (tmp_path / "lm.json").write_text(
        json.dumps(
            {
                "landmarks": [{"name": "A", "color": "red"}, {"name": "B", "color": "blue"}],
                "reference": ["A", "B"],
                "vision_error_deg": 4.0,
            }
        )
    )
    fields: dict[str, object] = {
        "port": port,
        "camera_source": str(tmp_path / "f_%04d.png"),
        "calibration_file": tmp_path / "cal.json",
        "landmark_file": tmp_path / "lm.json",
        "moves": 2,
        "distance_m": (0.01, 0.02),
        "seed": 5,
        "robot": {"model": "khepera2", "wheel_base_m": 0.06},
        "settings": RecordSettings(frame_rate_hz=20.0, png_level=0),
    }
    fields.update(changes)
    return RobotSessionSpec(**fields)  # type: ignore[arg-type]


def test_session_from_python_writes_a_complete_log(tmp_path: Path) -> None:
    fake = FakeKhepera(SystemClock(), np.random.default_rng(0))
    with fake.serve_pty() as server:
        spec = _spec(tmp_path, server.path)
        result = record_robot_session(tmp_path / "run.mcap", spec)
    assert result.movements == 2
    with LogReader(tmp_path / "run.mcap") as reader:
        session = reader.session()
        phases = [m.decode()["phase"] for m in reader.messages(["/robot/movement"])]
    assert phases == ["start", "end", "start", "end"]
    assert session.reference == ("A", "B")
    assert math.isclose(math.degrees(session.vision_error_rad), 4.0)
    assert session.doc["robot"]["port"] == server.path
    assert session.doc["robot"]["wheel_base_m"] == 0.06
    assert session.doc["recorder"] == {"png_level": 0, "seed": 5}
    assert not session.simulated


def test_bad_calibration_fails_before_robot_camera_or_log(tmp_path: Path) -> None:
    spec = _spec(tmp_path, "/dev/null/no-robot")
    (tmp_path / "cal.json").write_text(json.dumps({"model": "unwrapped", "width": W}))
    with pytest.raises(CalibrationError, match="field 'height': is missing"):
        record_robot_session(tmp_path / "run.mcap", spec)
    assert not (tmp_path / "run.mcap").exists()
