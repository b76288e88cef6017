"""CLI polish: close-match suggestions, progress bars on a terminal only, option ranges, quiet
OpenCV, and the first output that says what FL and "landmarks mapped" mean.

Progress bars are looked for on a real pseudo-terminal (``pty``), the way a user sees them, and
looked for in vain on a pipe.
"""

from __future__ import annotations

import fcntl
import json
import os
import pty
import re
import struct
import subprocess
import sys
import termios
from pathlib import Path

import pytest
from click.testing import CliRunner
from viewer import needs_viewer

from replay.cli import cli

BSLAM = [sys.executable, "-m", "replay.cli"]
#: what tqdm draws: "NAME:  40%|████      | 4/10 [00:01<00:01, 3.2move/s]"
BAR = re.compile(r"\d+%\|.*\| *\d+/(\d+) \[")


def _on_terminal(args: list[str], cwd: Path) -> tuple[int, str, str]:
    """Run ``args`` with stderr on a pseudo-terminal; (exit code, stdout, what the terminal got)."""
    master, slave = pty.openpty()
    # a terminal of 100 columns (a new pseudo-terminal has 0, and tqdm would draw nothing)
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 30, 100, 0, 0))
    proc = subprocess.Popen(
        args, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=slave, cwd=cwd
    )
    os.close(slave)
    chunks = []
    while True:
        try:
            data = os.read(master, 65536)
        except OSError:  # EIO: the child closed the terminal
            break
        if not data:
            break
        chunks.append(data)
    assert proc.stdout is not None
    out = proc.stdout.read().decode()
    code = proc.wait(timeout=300)
    os.close(master)
    return code, out, b"".join(chunks).decode(errors="replace")


def _piped(args: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(args, capture_output=True, text=True, cwd=cwd, timeout=300, check=False)


@pytest.mark.parametrize(
    ("typed", "hint"),
    [
        ("infos", "Did you mean 'info'?"),
        ("proces", "Did you mean 'process'?"),
        ("rcord", "Did you mean 'record' or 'recover'?"),
        ("xyzzy", None),
    ],
)
def test_unknown_command_suggests_close_ones(typed: str, hint: str | None) -> None:
    result = CliRunner().invoke(cli, [typed])
    assert result.exit_code == 2
    first = result.output.splitlines()[0]
    assert first == f"Error: No such command '{typed}'." + (f" {hint}" if hint else "")


def test_unknown_scenario_lists_the_built_in_ones(tmp_path: Path) -> None:
    result = CliRunner().invoke(
        cli, ["simulate", "--scenario", "papr", "--out", str(tmp_path / "x.mcap")]
    )
    assert result.exit_code == 1
    assert result.output == (
        "Error: 'papr' is neither a scenario file nor a built-in scenario; did you mean "
        "'paper'? the built-in ones: paper, paper_omni, coded_3x2\n"
    )
    assert not (tmp_path / "x.mcap").exists()


def test_turn_range_is_shown_and_enforced() -> None:
    help_text = CliRunner().invoke(cli, ["record", "--help"]).output
    assert "[-180.0<=x<=180.0]" in help_text
    assert "None" not in help_text  # click's "[x<=None]" of an unbounded float is gone
    result = CliRunner().invoke(
        cli,
        [
            *("record", "--port", "p", "--camera", "0", "--out", "o.mcap"),
            *("--calibration", "c", "--landmarks", "l", "--turn-deg", "400"),
        ],
    )
    assert result.exit_code == 2
    assert "400.0 is not in the range -180.0<=x<=180.0" in result.output


def test_a_missing_camera_is_one_line_without_opencv_warnings(tmp_path: Path) -> None:
    (tmp_path / "cal.json").write_text(
        json.dumps({"model": "unwrapped", "width": 32, "height": 16})
    )
    (tmp_path / "lms.json").write_text(
        json.dumps(
            {
                "landmarks": [{"name": "A", "color": "red"}, {"name": "B", "color": "blue"}],
                "reference": ["A", "B"],
                "vision_error_deg": 2.5,
            }
        )
    )
    env = {k: v for k, v in os.environ.items() if k != "OPENCV_LOG_LEVEL"}
    args = [*BSLAM, "record", "--port", "p", "--camera", "63", "--out", "x.mcap"]
    args += ["--calibration", "cal.json", "--landmarks", "lms.json"]
    done = subprocess.run(args, capture_output=True, text=True, cwd=tmp_path, env=env, check=False)
    assert done.returncode == 1
    assert done.stderr.startswith("Error: cannot open camera 63: ")
    assert done.stderr.count("\n") == 1, done.stderr  # OpenCV printed "[ WARN:0@...]" before


def test_first_output_explains_fl_and_the_landmark_count(small_log: Path, tmp_path: Path) -> None:
    out = tmp_path / "s.json"
    result = CliRunner().invoke(cli, ["process", str(small_log), "--summary", str(out)])
    assert result.exit_code == 0, result.output
    mapped = sorted(json.loads(out.read_text())["landmarks"])
    assert mapped == ["L3", "L4"]  # the catalog's four, less the reference pair L1, L2
    (line,) = result.output.splitlines()
    assert ", 2 landmarks mapped besides the reference pair L1, L2" in line


@pytest.mark.slow
@needs_viewer
def test_long_commands_draw_a_bar_on_a_terminal_only(tmp_path: Path) -> None:
    made = _piped(
        [*BSLAM, "simulate", "--scenario", "paper", "--seed", "1", "--out", "sim.mcap"], tmp_path
    )
    assert made.returncode == 0, made.stderr
    assert not BAR.search(made.stderr)  # the recording's bar: not on a pipe
    for args in (
        ["replay", "sim.mcap", "--save", "sim.rrd"],
        ["process", "sim.mcap", "--summary", "s.json"],
        ["process", "sim.mcap", "--summary", "w.json", "--from", "m2", "--to", "m7"],
    ):
        code, _, screen = _on_terminal([*BSLAM, *args], tmp_path)
        assert code == 0, screen
        totals = {m.group(1) for m in BAR.finditer(screen)}
        assert totals == ({"6"} if "--from" in args else {"10"}), (args, screen)
        piped = _piped(
            [
                *BSLAM,
                *[a.replace(".", "2.", 1) if a.endswith(("rrd", "json")) else a for a in args],
            ],
            tmp_path,
        )
        assert piped.returncode == 0, piped.stderr
        assert not BAR.search(piped.stderr), piped.stderr


@pytest.mark.parametrize("command", ["replay", "demo"])
def test_without_rerun_the_viewer_commands_name_the_extra(
    small_log: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, command: str
) -> None:
    monkeypatch.setitem(sys.modules, "rerun", None)  # `import rerun` now fails, as uninstalled
    out = tmp_path / "out"
    args = ["replay", str(small_log), "--save", str(out)] if command == "replay" else []
    args = args or ["demo", "--out", str(out)]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 1
    assert result.output == (
        f"Error: bslam {command} needs rerun, which is not installed; install the 'viewer' "
        "extra: pip install 'bearing-slam[viewer]'\n"
    )
    assert not out.exists()
