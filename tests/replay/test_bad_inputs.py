"""Each bad input gives exit 1 and one clear line (through click's CliRunner)."""

from __future__ import annotations

import json
import shlex
from pathlib import Path

import pytest
from click.testing import CliRunner
from logfactory import session_doc, write_log
from mcap.reader import make_reader
from mcap.writer import Writer
from viewer import needs_viewer

from data_schemas.mcap.layout import MESSAGE_HEADER
from replay.cli import cli


def _raw_mcap(path: Path, metadata: dict[str, str] | None, schema: str = "bslam.Movement") -> Path:
    with path.open("wb") as f:
        w = Writer(f)
        w.start()
        if metadata is not None:
            w.add_metadata("bslam.session", metadata)
        sid = w.register_schema(schema, "jsonschema", b"{}")
        cid = w.register_channel("/robot/movement", "json", sid)
        w.add_message(cid, 1, b"{}", 1)
        w.finish()
    return path


def _no_calibration() -> dict[str, str]:
    doc = session_doc()
    del doc["camera"]["calibration"]
    return {"json": json.dumps(doc)}


def _damaged(log: Path) -> Path:
    """``log`` with its first movement message overwritten where the index points at it."""
    data = bytearray(log.read_bytes())
    with log.open("rb") as f:
        _, _, first = next(make_reader(f).iter_messages(topics=["/robot/movement"]))
    record = data.index(first.data) - MESSAGE_HEADER.size
    data[record] = 0x7F  # no longer a message record
    log.write_bytes(data)
    return log


def _bad(tmp_path: Path, kind: str) -> Path:
    if kind == "not-mcap":
        p = tmp_path / "notes.mcap"
        p.write_text("hello, not a log\n")
        return p
    if kind == "shorter-than-magic":
        p = tmp_path / "tiny.mcap"
        p.write_bytes(b"\x89MCA")
        return p
    if kind == "magic-only":  # a recording killed right after it opened the file
        p = tmp_path / "started.mcap"
        p.write_bytes(b"\x89MCAP0\r\n")
        return p
    if kind == "unfinished":
        return write_log(tmp_path / "cut.mcap", finish=False)
    if kind == "no-metadata":
        return _raw_mcap(tmp_path / "bare.mcap", None)
    if kind == "no-calibration":
        return _raw_mcap(tmp_path / "nocal.mcap", _no_calibration())
    if kind == "unknown-schema":
        return _raw_mcap(tmp_path / "acme.mcap", {"json": json.dumps(session_doc())}, "acme.Widget")
    if kind == "missing":
        return tmp_path / "nowhere.mcap"
    if kind == "damaged":
        return _damaged(write_log(tmp_path / "damaged.mcap"))
    raise AssertionError(kind)


EXPECTED = {
    "not-mcap": "is not an MCAP file",
    "shorter-than-magic": "is not an MCAP file",
    "magic-only": "0 messages are readable; run `bslam recover",
    "unfinished": "bslam recover",
    "no-metadata": "no 'bslam.session'",
    "no-calibration": "no camera calibration",
    "unknown-schema": "'acme.Widget', which this version of bearing-slam does not know",
    "missing": "no such file",
    "damaged": "is corrupt: chunk at bytes",
}


@pytest.mark.parametrize("command", ["process", pytest.param("replay", marks=needs_viewer)])
@pytest.mark.parametrize("kind", sorted(EXPECTED))
def test_bad_log_is_one_line_exit_1(tmp_path: Path, kind: str, command: str) -> None:
    log = _bad(tmp_path, kind)
    args = [command, str(log)]
    if command == "replay":
        args += ["--save", str(tmp_path / "out.rrd")]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 1, result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1, result.output
    assert lines[0].startswith("Error: ")
    assert EXPECTED[kind].lower() in lines[0].lower()


@pytest.mark.parametrize("command", ["process", "info"])
def test_recover_hint_is_a_command_a_shell_can_run(tmp_path: Path, command: str) -> None:
    folder = tmp_path / "my logs"
    folder.mkdir()
    log = write_log(folder / "cut $HOME.mcap", finish=False)
    result = CliRunner().invoke(cli, [command, str(log)])
    assert result.exit_code == 1, result.output
    hint = result.output.split("`")[-2]  # the one back-quoted command of the error line
    assert shlex.split(hint) == ["bslam", "recover", str(log), "FIXED.mcap"]


def test_bad_option_is_usage_error(small_log: Path) -> None:
    result = CliRunner().invoke(cli, ["process", str(small_log), "--prior", "flat"])
    assert result.exit_code == 2
