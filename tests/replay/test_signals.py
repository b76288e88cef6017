"""SIGTERM and Ctrl-C (SIGINT) to long commands, in a subprocess: every process of the command
stops (worker processes included), exit 128 + the signal, one line on stderr."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from viewer import needs_viewer

ROOT = Path(__file__).resolve().parents[2]
REGRESS = ROOT / "tests" / "data" / "regress"
#: Not a speed goal (stopping takes about 0.2 s): a stop that hangs fails well before pytest's.
HANG_S = 10.0


def _start(args: list[str], cwd: Path) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "replay.cli", *args],
        cwd=cwd,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # its own session: every process it starts can be found
    )


def _session(sid: int) -> list[int]:
    out = subprocess.run(["pgrep", "-s", str(sid)], capture_output=True, text=True).stdout
    return [int(p) for p in out.split()]


def _wait_for_processes(proc: subprocess.Popen[str], n: int) -> None:
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        if len(_session(proc.pid)) >= n:
            time.sleep(0.5)  # let the workers start on their tasks
            return
        time.sleep(0.05)
    raise AssertionError(f"the command never had {n} processes")


def _stop(proc: subprocess.Popen[str], signum: int) -> str:
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=HANG_S)
    time.sleep(0.2)
    assert _session(proc.pid) == [], "processes left behind"
    assert proc.returncode == 128 + signum, err
    assert "Traceback" not in err, err
    return err


@pytest.mark.slow  # about 5 s: the experiment's imports before its workers start
def test_sigterm_to_experiment_with_workers(tmp_path: Path) -> None:
    signum = signal.SIGTERM
    args = ["experiment", "paper", "--out", str(tmp_path / "exp"), "--runs", "40"]
    proc = _start([*args, "--workers", "2", "--quiet", "--n-l-values", ""], tmp_path)
    _wait_for_processes(proc, 3)  # the command and its two workers
    err = _stop(proc, signum)
    assert "terminated" in re.split(r"[\r\n]", err)  # --quiet: no bar


@pytest.mark.parametrize(
    "signum", [signal.SIGTERM, pytest.param(signal.SIGINT, marks=pytest.mark.slow)]
)
def test_stop_process_with_workers(tmp_path: Path, signum: int) -> None:
    logs = tmp_path / "logs"
    logs.mkdir()
    for i in range(60):
        shutil.copy(REGRESS / "unwrapped.mcap", logs / f"run_{i:02d}.mcap")
    proc = _start(
        ["process", str(logs), "--summary", str(tmp_path / "maps"), "--workers", "2"], tmp_path
    )
    _wait_for_processes(proc, 3)
    err = _stop(proc, signum)
    word = "terminated" if signum == signal.SIGTERM else "interrupted"
    assert err.count(word) == 1  # after the progress bar


def test_sigterm_to_simulate_finishes_the_log(tmp_path: Path) -> None:
    scenario = json.loads((ROOT / "recorder/sim/scenarios/paper.json").read_text())
    scenario["trajectory"]["moves"] = 100_000
    (tmp_path / "long.json").write_text(json.dumps(scenario))
    out = tmp_path / "sim.mcap"
    proc = _start(["simulate", "--scenario", "long.json", "--out", str(out)], tmp_path)
    deadline = time.monotonic() + 60
    while not (out.exists() and out.stat().st_size > 200_000):
        assert time.monotonic() < deadline and proc.poll() is None, proc.communicate()
        time.sleep(0.05)
    err = _stop(proc, signal.SIGTERM)
    assert "recording stopped by SIGTERM" in err
    from data_schemas.mcap.info import log_summary

    assert log_summary(out).finished


@pytest.mark.parametrize(
    ("target", "args"),
    [
        ("replay.process.process_log", ["process", "{log}"]),
        pytest.param(
            "replay.rerun_out.replay_log",
            ["replay", "{log}", "--save", "{tmp}/o.rrd"],
            marks=needs_viewer,
        ),
        ("replay.regress.run_regression", ["regress", "{regress}"]),
        (
            "recorder.sim.simulate.simulate_to_file",
            ["simulate", "--scenario", "paper", "--out", "{tmp}/s.mcap"],
        ),
        ("data_schemas.mcap.info.log_summary", ["info", "{log}"]),
    ],
)
def test_ctrl_c_exits_130_everywhere(
    tmp_path: Path, small_log: Path, monkeypatch: pytest.MonkeyPatch, target: str, args: list[str]
) -> None:
    """Ctrl-C wherever a command is: one line, exit 130, no traceback (CliRunner)."""
    from click.testing import CliRunner

    from replay.cli import cli

    def interrupted(*a: object, **k: object) -> None:
        raise KeyboardInterrupt

    module, name = target.rsplit(".", 1)
    monkeypatch.setattr(f"{module}.{name}", interrupted)
    fill = {"log": str(small_log), "tmp": str(tmp_path), "regress": str(REGRESS)}
    result = CliRunner().invoke(cli, [a.format(**fill) for a in args])
    assert result.exit_code == 130, result.output
    assert [line for line in result.output.splitlines() if line.strip()] == ["interrupted"]
