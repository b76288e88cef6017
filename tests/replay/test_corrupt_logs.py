"""process, replay and info see a corrupt chunk; --skip-corrupt processes the rest, warned."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner
from mcap.reader import make_reader
from viewer import needs_viewer

from replay.cli import cli


def _flip_in_movement(log: Path, out: Path) -> Path:
    """``log`` with one digit of its second movement message changed (as on a bad disk)."""
    data = bytearray(log.read_bytes())
    with log.open("rb") as f:
        moves = [m for _, _, m in make_reader(f).iter_messages(topics=["/robot/movement"])]
    at = data.index(moves[1].data) + moves[1].data.index(b"distance_m") + 14
    assert chr(data[at]).isdigit()
    data[at] = ord("7") if data[at] != ord("7") else ord("3")
    out.write_bytes(bytes(data))
    return out


@pytest.mark.parametrize("command", ["process", pytest.param("replay", marks=needs_viewer), "info"])
def test_corrupt_log_is_refused_in_one_line(small_log: Path, tmp_path: Path, command: str) -> None:
    broken = _flip_in_movement(small_log, tmp_path / "broken.mcap")
    args = [command, str(broken)]
    if command == "replay":
        args += ["--save", str(tmp_path / "out.rrd")]
    if command == "info":
        args += ["--check"]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 1, result.output
    last = result.output.strip().splitlines()[-1]
    assert last.startswith("Error: broken.mcap is corrupt: chunk at bytes") or (
        command == "info" and "is corrupt: chunk at bytes" in last
    )
    assert "CRC mismatch, log time" in last and "/robot/movement" in last
    if command == "info":
        assert "CORRUPT" in result.output and "finished" not in result.output
    else:
        assert len(result.output.strip().splitlines()) == 1 and "--skip-corrupt" in last
    assert not (tmp_path / "out.rrd").exists()


@pytest.mark.parametrize("command", ["process", pytest.param("replay", marks=needs_viewer)])
def test_skip_corrupt_warns_and_says_what_was_skipped(
    small_log: Path, tmp_path: Path, command: str
) -> None:
    broken = _flip_in_movement(small_log, tmp_path / "broken.mcap")
    args = [command, str(broken), "--skip-corrupt"]
    if command == "replay":
        args += ["--save", str(tmp_path / "out.rrd")]
    result = CliRunner().invoke(cli, args)
    assert "warning: broken.mcap: skipped chunk at bytes" in result.output
    assert "CRC mismatch" in result.output and "/sim/ground_truth; 24 messages" in result.output
    # the damaged chunk held every message of this short log: an empty map, nothing from it
    assert result.exit_code == 0, result.output
    assert "0/0 movements used" in result.output or '"movements": []' in result.output
