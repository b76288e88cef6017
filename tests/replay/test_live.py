"""Live mode on real processes: a follower beside `bslam simulate --speed`, killed recorders and
killed followers."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner

from data_schemas.mcap.follow import FollowedLog
from replay.cli import cli
from replay.process import process_log
from replay.records import MethodConfig, MovementRecord
from replay.sinks.summary import SummarySink

METHOD = MethodConfig(n_l=150, seed=3)
BSLAM = [sys.executable, "-m", "replay.cli"]


def _simulate(out: Path, *extra: str) -> subprocess.Popen[str]:
    args = ["simulate", "--scenario", "paper", "--seed", "5", "--out", str(out), *extra]
    return subprocess.Popen(
        [*BSLAM, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )


def _children(pid: int) -> list[tuple[int, str]]:
    """(pid, command line) of the processes whose parent is ``pid``."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            cmdline = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            continue
        if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
            found.append((int(entry.name), cmdline))
    return found


class _Arrivals(SummarySink):
    """A summary sink that also notes whether the recorder was still running at each movement."""

    def __init__(self, recorder: subprocess.Popen[str]) -> None:
        super().__init__()
        self.recorder = recorder
        self.while_recording: list[bool] = []

    def movement(self, record: MovementRecord) -> None:
        super().movement(record)
        self.while_recording.append(self.recorder.poll() is None)


def test_follower_beside_a_simulation_gives_the_offline_result(tmp_path: Path) -> None:
    out = tmp_path / "live.mcap"
    recorder = _simulate(out, "--speed", "6")
    try:
        sink = _Arrivals(recorder)
        with FollowedLog(out, idle_timeout_s=5) as log:
            followed = process_log(log, METHOD, extra_sinks=(sink,)).to_json()
            assert log.end == "finished"
    finally:
        assert recorder.wait(30) == 0, recorder.stderr.read() if recorder.stderr else ""
    assert len(sink.while_recording) == 10
    assert sink.while_recording[0], "the follower only started after the recording ended"
    assert process_log(out, METHOD).to_json() == followed


def test_killed_recording_ends_the_follower_with_a_clear_line(tmp_path: Path) -> None:
    out = tmp_path / "killed.mcap"
    recorder = _simulate(out, "--speed", "2")
    try:
        deadline = time.monotonic() + 20
        while (not out.exists() or out.stat().st_size < 40_000) and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        recorder.send_signal(signal.SIGKILL)
        recorder.wait()
    args = ["process", str(out), "--follow", "--idle-timeout", "0.5"]
    t0 = time.monotonic()
    result = CliRunner().invoke(cli, args)
    assert time.monotonic() - t0 >= 0.5
    assert result.exit_code == 1
    assert "killed.mcap has not grown for 0.5 s: stopped following" in result.stderr
    doc = json.loads(result.stdout)
    assert doc["movements"], "the chunks written before the kill were processed"


@pytest.mark.slow  # real processes in real time: CI runs it with -m slow
def test_killing_the_live_follower_does_not_disturb_the_recording(tmp_path: Path) -> None:
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    live = _simulate(tmp_path / "a" / "s.mcap", "--speed", "6", "--live")
    deadline = time.monotonic() + 20
    follower: list[tuple[int, str]] = []
    while not follower and time.monotonic() < deadline and live.poll() is None:
        follower = [c for c in _children(live.pid) if "--follow" in c[1]]
        time.sleep(0.02)
    assert follower, "no follower process was started"
    os.kill(follower[0][0], signal.SIGKILL)
    _, err = live.communicate(timeout=60)
    assert live.returncode == 0, err
    assert err.count("live view stopped (follower exit -9); the recording goes on") == 1
    plain = _simulate(tmp_path / "b" / "s.mcap")
    assert plain.wait(60) == 0
    docs: list[dict[str, Any]] = [
        process_log(tmp_path / d / "s.mcap", METHOD).to_json() for d in "ab"
    ]
    assert docs[0] == docs[1]
    assert len(docs[0]["movements"]) == 10


@pytest.mark.slow  # real processes in real time: CI runs it with -m slow
def test_live_terminal_view_follows_to_the_end(tmp_path: Path) -> None:
    out = tmp_path / "view.mcap"
    live = _simulate(out, "--speed", "12", "--live")
    stdout, err = live.communicate(timeout=60)
    assert live.returncode == 0, err
    lines = [line for line in err.splitlines() if line.startswith("view.mcap: movement ")]
    assert [line.split()[2] for line in lines] == [str(i) for i in range(10)]
    assert f"{out} is finished (footer written)" in err
    assert re.fullmatch(rf"wrote {re.escape(str(out))}: 10 movements, \d+ frames", stdout.strip())


def test_live_options_are_checked() -> None:
    result = CliRunner().invoke(
        cli, ["simulate", "--scenario", "paper", "--out", "x.mcap", "--spawn"]
    )
    assert result.exit_code == 2 and "--spawn shows a live view: add --live" in result.output
    result = CliRunner().invoke(cli, ["process", "a.mcap", "b.mcap", "--follow"])
    assert result.exit_code == 2 and "--follow takes one LOG" in result.output


def _entities(rrd: Path) -> set[str]:
    import rerun as rr

    return {chunk.entity_path for chunk in rr.chunk.RrdReader(rrd).stream()}


@pytest.mark.slow  # real processes in real time: CI runs it with -m slow
def test_live_rerun_recording_has_the_offline_entities(tmp_path: Path) -> None:
    out, live_rrd, offline_rrd = tmp_path / "s.mcap", tmp_path / "live.rrd", tmp_path / "off.rrd"
    live = _simulate(out, "--speed", "20", "--live", "--save", str(live_rrd))
    _, err = live.communicate(timeout=120)
    assert live.returncode == 0, err
    result = CliRunner().invoke(cli, ["replay", str(out), "--save", str(offline_rrd)])
    assert result.exit_code == 0, result.output
    entities = _entities(live_rrd)
    assert entities == _entities(offline_rrd)
    assert {"camera/panorama", "map/estimates", "fr/cones/L3"} <= {e.strip("/") for e in entities}


def test_record_live_on_a_pty_robot(tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    from recorder.clock import SystemClock
    from recorder.sim.fake_khepera import FakeKhepera
    from tests.replay.test_cli_record_info import _inputs

    inputs = _inputs(tmp_path)
    out = tmp_path / "rec.mcap"
    fake = FakeKhepera(SystemClock(), np.random.default_rng(0))
    with fake.serve_pty() as server:
        args = ["record", "--port", server.path, "--camera", inputs["camera"], "--out", str(out)]
        args += ["--calibration", inputs["cal"], "--landmarks", inputs["lms"], "--moves", "2"]
        args += ["--distance", "0.02", "--turn-deg", "10", "--rate", "20", "--live"]
        result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    assert "wrote" in result.stdout and "2 movements" in result.stdout
    assert "live view stopped" not in result.stderr
    follower_err = capfd.readouterr().err  # the follower process writes to the terminal itself
    assert "rec.mcap: movement 1 skipped" in follower_err  # random frames: no landmark seen
    assert f"{out} is finished (footer written)" in follower_err
