"""`bslam record`, `info` and `recover` through click's CliRunner, on real files and a pty robot."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from data_schemas.codec import validate
from data_schemas.mcap.info import log_summary
from data_schemas.mcap.writer import LogWriter
from data_schemas.registry import TOPICS
from recorder.clock import SystemClock, VirtualClock
from recorder.sim.fake_khepera import FakeKhepera
from recorder.timebase import EpochClock
from replay.cli import cli
from tests.mcap_reader import LogReader
from tests.recorder.samples import make_session_doc, sample_messages


def _inputs(tmp_path: Path, frames: int = 40) -> dict[str, str]:
    rng = np.random.default_rng(2)
    for i in range(frames):
        cv2.imwrite(
            str(tmp_path / f"pano_{i:04d}.png"), rng.integers(0, 256, (16, 32, 3), np.uint8)
        )
    cal = tmp_path / "cal.json"
    cal.write_text(json.dumps({"model": "unwrapped", "width": 32, "height": 16}))
    lms = tmp_path / "landmarks.json"
    lms.write_text(
        json.dumps(
            {
                "landmarks": [{"name": "A", "color": "red"}, {"name": "B", "color": "blue"}],
                "reference": ["A", "B"],
                "vision_error_deg": 2.5,
            }
        )
    )
    return {"camera": str(tmp_path / "pano_%04d.png"), "cal": str(cal), "lms": str(lms)}


def test_record_on_a_pty_robot_then_info(tmp_path: Path) -> None:
    inputs = _inputs(tmp_path)
    fake = FakeKhepera(SystemClock(), np.random.default_rng(0))
    out = tmp_path / "rec.mcap"
    with fake.serve_pty() as server:
        result = CliRunner().invoke(
            cli,
            [
                "record",
                "--port",
                server.path,
                "--camera",
                inputs["camera"],
                "--out",
                str(out),
                "--calibration",
                inputs["cal"],
                "--landmarks",
                inputs["lms"],
                "--moves",
                "2",
                "--distance",
                "0.02",
                "--turn-deg",
                "10",
                "--rate",
                "20",
            ],
        )
    assert result.exit_code == 0, result.output
    assert "2 movements" in result.output
    with LogReader(out) as reader:
        session = reader.session()
        assert session.landmark_names() == ["A", "B"] and not session.simulated
        assert session.vision_error_rad == pytest.approx(np.radians(2.5))
        msgs = list(reader.messages())
    for m in msgs:
        validate(TOPICS[m.topic].schema, m.decode(), what=m.topic)
    assert "/sim/ground_truth" not in {m.topic for m in msgs}  # a real robot: no ground truth
    assert [m.decode()["phase"] for m in msgs if m.topic == "/robot/movement"] == [
        "start",
        "end",
    ] * 2

    info = CliRunner().invoke(cli, ["info", str(out)])
    assert info.exit_code == 0, info.output
    assert "finished (indexed)" in info.output
    assert "landmarks: A (red), B (blue); reference A, B; vision error 2.5 deg" in info.output
    counts = {c.topic: c.count for c in log_summary(out).channels}
    assert f"/robot/movement   bslam.Movement            {counts['/robot/movement']}" in info.output


def test_record_errors_are_one_line(tmp_path: Path) -> None:
    inputs = _inputs(tmp_path, frames=1)
    base = [
        "record",
        "--camera",
        inputs["camera"],
        "--calibration",
        inputs["cal"],
        "--landmarks",
        inputs["lms"],
        "--out",
        str(tmp_path / "x.mcap"),
    ]
    missing_port = CliRunner().invoke(cli, [*base, "--port", str(tmp_path / "ttyNONE")])
    assert missing_port.exit_code == 1
    assert missing_port.output.count("\n") == 1 and "does not exist" in missing_port.output
    bad_camera = CliRunner().invoke(
        cli, [*base[:2], str(tmp_path / "none_%04d.png"), *base[3:], "--port", "x"]
    )
    assert bad_camera.exit_code == 1 and "cannot open camera" in bad_camera.output
    (tmp_path / "cal.json").write_text(json.dumps({"model": "fisheye", "width": 3, "height": 3}))
    bad_cal = CliRunner().invoke(cli, [*base, "--port", "x"])
    assert bad_cal.exit_code == 1 and "calibration file" in bad_cal.output
    assert not (tmp_path / "x.mcap").exists()  # nothing was created for a failed start


def _log_with_chunks(path: Path, frames: int = 30) -> None:
    clock = EpochClock(VirtualClock())
    with LogWriter(path, make_session_doc(), clock=clock, chunk_bytes=3000) as log:
        for i in range(frames):
            log.write(
                "/camera/panorama",
                sample_messages(clock.monotonic_ns(), np.random.default_rng(i))["/camera/panorama"],
            )
            clock.sleep(0.05)


def test_info_and_recover_on_a_truncated_log(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    _log_with_chunks(path)
    broken = tmp_path / "broken.mcap"
    data = path.read_bytes()
    broken.write_bytes(data[: len(data) // 2])
    readable = log_summary(broken).message_count
    assert 0 < readable < 30

    info = CliRunner().invoke(cli, ["info", str(broken)])
    assert info.exit_code == 1
    assert "UNFINISHED" in info.output
    last = info.output.strip().splitlines()[-1]
    assert (
        f"unfinished (the recording was interrupted): {readable} messages are readable" in last
        and "bslam recover" in last
    )

    fixed = tmp_path / "fixed.mcap"
    rec = CliRunner().invoke(cli, ["recover", str(broken), str(fixed)])
    assert rec.exit_code == 3, rec.output  # the rest of the cut chunk is lost
    assert f"recovered {readable} messages" in rec.output
    assert "lost: cut chunk at bytes" in rec.output
    again = CliRunner().invoke(cli, ["info", str(fixed)])
    assert again.exit_code == 0 and "finished (indexed)" in again.output


def test_info_on_non_mcap_and_missing_files(tmp_path: Path) -> None:
    text = tmp_path / "notes.mcap"
    text.write_text("not a log")
    result = CliRunner().invoke(cli, ["info", str(text)])
    assert result.exit_code == 1
    assert result.output == f"Error: {text} is not an MCAP file (bad magic bytes)\n"
    missing = CliRunner().invoke(cli, ["info", str(tmp_path / "none.mcap")])
    assert missing.exit_code == 1 and "cannot open log" in missing.output
    nothing = CliRunner().invoke(cli, ["recover", str(text), str(tmp_path / "out.mcap")])
    assert nothing.exit_code == 1 and "not an MCAP file" in nothing.output
