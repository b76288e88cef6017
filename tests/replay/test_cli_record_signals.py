"""`bslam record` in a subprocess against the fake Khepera on a pty: SIGTERM, SIGINT, SIGKILL and
a full disk (RLIMIT_FSIZE). Nothing already recorded is lost."""

from __future__ import annotations

import json
import os
import resource
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest

from data_schemas.codec import validate
from data_schemas.errors import NotMcapError
from data_schemas.mcap.info import log_summary
from data_schemas.mcap.recover import recover_log
from data_schemas.registry import TOPICS
from recorder.clock import SystemClock
from recorder.sim.fake_khepera import FakeKhepera
from tests.mcap_reader import LogReader

ROOT = Path(__file__).resolve().parents[2]
H, W = 48, 96


@pytest.fixture
def robot_port() -> Iterator[str]:
    fake = FakeKhepera(SystemClock(), np.random.default_rng(0))
    with fake.serve_pty() as server:
        yield server.path


def _command(tmp_path: Path, port: str, out: Path) -> list[str]:
    rng = np.random.default_rng(4)
    distinct = [tmp_path / f"distinct_{k}.png" for k in range(8)]
    for path in distinct:
        cv2.imwrite(str(path), rng.integers(0, 256, (H, W, 3), np.uint8))
    for i in range(2000):  # more frames than any of these runs reads (hard links: cheap)
        os.link(distinct[i % 8], tmp_path / f"f_{i:04d}.png")
    (tmp_path / "cal.json").write_text(json.dumps({"model": "unwrapped", "width": W, "height": H}))
    (tmp_path / "lm.json").write_text(
        json.dumps(
            {
                "landmarks": [{"name": "A", "color": "red"}, {"name": "B", "color": "green"}],
                "reference": ["A", "B"],
            }
        )
    )
    return [
        sys.executable,
        "-m",
        "replay.cli",
        "record",
        "--port",
        port,
        "--camera",
        str(tmp_path / "f_%04d.png"),
        "--calibration",
        str(tmp_path / "cal.json"),
        "--landmarks",
        str(tmp_path / "lm.json"),
        "--out",
        str(out),
        "--moves",
        "0",
        "--distance",
        "0.2",
        "--rate",
        "30",
        "--png-level",
        "0",
    ]


def _start(cmd: list[str], preexec: Callable[[], None] | None = None) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen(
        cmd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=preexec,
    )


def _wait_for_messages(out: Path, proc: subprocess.Popen[str], n: int) -> None:
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        try:
            if out.exists() and log_summary(out).message_count >= n:
                return
        except NotMcapError:
            pass  # just created: its magic bytes are not written yet
        time.sleep(0.1)
    raise AssertionError("the recorder wrote nothing")


def _check_all_valid(path: Path) -> int:
    with LogReader(path) as reader:
        msgs = list(reader.messages())
    for m in msgs:
        validate(TOPICS[m.topic].schema, m.decode(), what=m.topic)
    return len(msgs)


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_stop_signal_finishes_an_indexed_log(tmp_path: Path, robot_port: str, signum: int) -> None:
    out = tmp_path / "rec.mcap"
    proc = _start(_command(tmp_path, robot_port, out))
    _wait_for_messages(out, proc, 40)
    before = log_summary(out).message_count
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 128 + signum, err
    assert f"recording stopped by {signal.Signals(signum).name}" in err
    assert _check_all_valid(out) >= before  # indexed (LogReader raises otherwise), nothing lost
    with LogReader(out) as reader:
        msgs = list(reader.messages())
    last_log = [m.decode() for m in msgs if m.topic == "/log"][-1]
    assert f"stopped by {signal.Signals(signum).name}" in last_log["message"]
    commands = [m.decode() for m in msgs if m.topic == "/robot/command"]
    assert commands[-1]["request"] == "D,0,0"  # the motors were stopped


@pytest.mark.slow
def test_sigkill_loses_at_most_the_last_second(tmp_path: Path, robot_port: str) -> None:
    out = tmp_path / "rec.mcap"
    proc = _start(_command(tmp_path, robot_port, out))
    _wait_for_messages(out, proc, 40)
    time.sleep(1.5)
    kill_ns = time.time_ns()
    proc.kill()
    proc.communicate(timeout=30)
    summary = log_summary(out)
    assert not summary.finished
    assert summary.end_ns is not None and summary.end_ns >= kill_ns - 1_000_000_000
    fixed = tmp_path / "fixed.mcap"
    report = recover_log(out, fixed)
    assert report.messages == summary.message_count
    assert _check_all_valid(fixed) == summary.message_count


def test_disk_full_gives_one_line_and_a_readable_log(tmp_path: Path, robot_port: str) -> None:
    out = tmp_path / "rec.mcap"
    limit = 400_000
    cmd = _command(tmp_path, robot_port, out)

    def small_disk() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    proc = _start(cmd, preexec=small_disk)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 1, err
    line = err.strip().splitlines()[-1]
    assert line.startswith("Error: disk full while writing") and "bslam recover" in line
    assert out.stat().st_size <= limit
    summary = log_summary(out)
    assert not summary.finished and summary.message_count > 0
    assert summary.trailing_bytes == 0  # cut back to the end of the last complete chunk
    assert f"{summary.message_count} messages kept" in line
