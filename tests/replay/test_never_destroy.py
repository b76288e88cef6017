"""No command destroys data: inputs, links to them, existing outputs, colliding outputs."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner, Result
from viewer import HAS_VIEWER, needs_experiments, needs_viewer

from data_schemas.errors import OutputError
from data_schemas.outputs import OutputGuard, move_aside
from recorder.clock import SystemClock
from recorder.sim.fake_khepera import FakeKhepera
from replay.cli import cli
from tests.mcap_reader import LogReader
from tests.replay.test_cli_record_info import _inputs


def _run(*args: str | Path) -> Result:
    return CliRunner().invoke(cli, [str(a) for a in args])


def _one_line_error(result: Result, text: str) -> None:
    assert result.exit_code == 1, result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error: "), result.output
    assert text.lower() in lines[0].lower(), lines[0]


@pytest.fixture()
def log(small_log: Path, tmp_path: Path) -> Path:
    copy = tmp_path / "run.mcap"
    shutil.copyfile(small_log, copy)
    return copy


def _links(log: Path) -> dict[str, Path]:
    sym = log.with_name("sym.mcap")
    sym.symlink_to(log)
    hard = log.with_name("hard.mcap")
    os.link(log, hard)
    return {"same": log, "symlink": sym, "hardlink": hard}


@pytest.mark.parametrize("kind", ["same", "symlink", "hardlink"])
def test_outputs_never_land_on_the_input(log: Path, tmp_path: Path, kind: str) -> None:
    before = log.read_bytes()
    target = _links(log)[kind]
    commands = [
        ("process", log, "--summary", target),
        ("process", log, "--out", target),
        ("process", log, "--out", target, "--force"),
        ("replay", log, "--save", target, "--force"),
        ("recover", log, target),
        ("recover", log, target, "--force"),
    ]
    for args in commands if HAS_VIEWER else [c for c in commands if c[0] != "replay"]:
        _one_line_error(_run(*args), "(or a link to it): choose another output path")
        assert log.read_bytes() == before, args


def test_existing_outputs_are_refused_unless_forced(log: Path, tmp_path: Path) -> None:
    old = tmp_path / "old.txt"
    for args in [
        ("process", log, "--summary", old),
        ("process", log, "--out", old),
        *([("replay", log, "--save", old)] if HAS_VIEWER else []),
        ("recover", log, old),
        ("simulate", "--scenario", "paper", "--out", old),
    ]:
        old.write_text("precious")
        _one_line_error(_run(*args), f"{old} exists: pass --force to replace it")
        assert old.read_text() == "precious", args
    forced = _run("process", log, "--summary", old, "--force")
    assert forced.exit_code == 0, forced.output
    assert old.read_text().startswith("{")
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no leftovers


@needs_viewer
def test_demo_refuses_before_simulating(tmp_path: Path) -> None:
    (tmp_path / "demo.summary.json").write_text("{}")
    result = _run("demo", "--out", tmp_path)
    _one_line_error(result, "demo.summary.json exists: pass --force")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo.summary.json"]


def test_two_logs_with_one_output_name_are_refused(small_log: Path, tmp_path: Path) -> None:
    for folder in ("A", "B"):
        (tmp_path / folder).mkdir()
        shutil.copyfile(small_log, tmp_path / folder / "x.mcap")
    out = tmp_path / "d"
    result = _run("process", tmp_path / "A" / "x.mcap", tmp_path / "B" / "x.mcap", "--summary", out)
    _one_line_error(result, "would be written twice")
    assert list(out.iterdir()) == []


def test_unusable_output_paths_are_one_line(log: Path, tmp_path: Path) -> None:
    _one_line_error(_run("process", log, "--summary", "/dev/null"), "is not a regular file")
    missing = tmp_path / "no" / "such" / "s.json"
    _one_line_error(_run("process", log, "--summary", missing), "does not exist")
    long = tmp_path / ("x" * 300 + ".json")
    _one_line_error(_run("process", log, "--summary", long), "file name too long")
    folder = tmp_path / "folder.json"
    folder.mkdir()
    _one_line_error(_run("process", log, "--summary", folder), "not a regular file")


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_unwritable_folder_is_one_line(log: Path, tmp_path: Path) -> None:
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        _one_line_error(_run("process", log, "--summary", locked / "s.json"), "not writable")
    finally:
        locked.chmod(0o755)


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux's /proc")
@pytest.mark.parametrize(
    ("command", "option", "name"),
    [
        ("process", "--out", "d.mcap"),
        ("process", "--summary", "s.json"),
        pytest.param("replay", "--save", "r.rrd", marks=needs_viewer),
    ],
)
def test_a_folder_that_refuses_new_files_is_one_line(
    log: Path, command: str, option: str, name: str
) -> None:
    # /proc exists and is a folder, but no one (root included) can create a file in it: the
    # temporary file beside the output cannot be made
    _one_line_error(_run(command, log, option, Path("/proc") / name), f"cannot write /proc/{name}")


def test_interrupted_write_leaves_the_old_file_whole(tmp_path: Path) -> None:
    out = tmp_path / "s.json"
    out.write_text("old")
    guard = OutputGuard(force=True)
    guard.claim(out)
    with pytest.raises(KeyboardInterrupt), guard.writing(out) as stream:
        stream.write(b"half of the new")
        raise KeyboardInterrupt
    assert out.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.json"]
    with guard.writing(out) as stream:
        stream.write(b"new")
    assert out.read_text() == "new"


def test_recorder_moves_an_old_log_aside(tmp_path: Path) -> None:
    log = tmp_path / "run.mcap"
    assert move_aside(log) is None
    log.write_bytes(b"session 1")
    (tmp_path / "run.old-1.mcap").write_bytes(b"session 0")
    aside = move_aside(log)
    assert aside == tmp_path / "run.old-2.mcap"
    assert aside.read_bytes() == b"session 1" and not log.exists()
    assert (tmp_path / "run.old-1.mcap").read_bytes() == b"session 0"


def test_guard_checks_every_input(tmp_path: Path) -> None:
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    a.write_bytes(b"a")
    b.write_bytes(b"b")
    guard = OutputGuard([a, b])
    with pytest.raises(OutputError, match="is the input"):
        guard.claim(b)
    guard.claim(tmp_path / "c.json")
    with pytest.raises(OutputError, match="written twice"):
        guard.claim(tmp_path / "." / "c.json")


@needs_experiments
def test_experiment_refuses_a_folder_of_earlier_results(tmp_path: Path) -> None:
    (tmp_path / "results.json").write_text("{}")
    result = _run("experiment", "paper", "--out", tmp_path, "--runs", "1")
    _one_line_error(result, "holds earlier results; pass --force")
    assert (tmp_path / "results.json").read_text() == "{}"


def _record(inputs: dict[str, str], out: Path, *extra: str) -> Result:
    fake = FakeKhepera(SystemClock(), np.random.default_rng(0))
    with fake.serve_pty() as server:
        return _run(
            "record",
            "--port",
            server.path,
            "--camera",
            inputs["camera"],
            "--out",
            out,
            "--calibration",
            inputs["cal"],
            "--landmarks",
            inputs["lms"],
            "--moves",
            "1",
            "--distance",
            "0.02",
            "--turn-deg",
            "10",
            *extra,
        )


def test_record_never_overwrites_a_log(tmp_path: Path) -> None:
    inputs = _inputs(tmp_path, frames=20)
    out = tmp_path / "run.mcap"
    first = _record(inputs, out)
    assert first.exit_code == 0, first.output
    session = out.read_bytes()
    _one_line_error(_record(inputs, out), f"{out} exists: pass --force")
    assert out.read_bytes() == session
    forced = _record(inputs, out, "--force")
    assert forced.exit_code == 0, forced.output
    aside = tmp_path / "run.old-1.mcap"
    assert f"moved the existing {out} aside to {aside}" in forced.output
    assert aside.read_bytes() == session and out.read_bytes() != session
    with LogReader(out) as reader:  # the new session, finished
        assert reader.finished
    _one_line_error(_record(inputs, Path(inputs["cal"]), "--force"), "is the input")
