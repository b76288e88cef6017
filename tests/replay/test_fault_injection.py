"""Fault injection: races for one output, full disks (RLIMIT_FSIZE), bombs, FIFOs, nesting,
links, stale temporary files, a log being recorded.

Every case must end in one line on stderr, a documented exit code, within seconds, with no
output under its final name unless complete and no input changed. The commands run as real
processes where a process is what is attacked (a file-size limit, a FIFO, memory); the oracle is
what the file system holds afterwards, read with ``os`` and the ``mcap`` library.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import math
import os
import signal
import stat
import subprocess
import sys
import time
import zlib
from collections.abc import Iterator
from pathlib import Path

import pytest
from click.testing import CliRunner
from mcap.reader import make_reader

from data_schemas.errors import OutputError
from data_schemas.mcap.compression import MAX_CHUNK_BYTES, DecompressionError, decompress
from data_schemas.mcap.writer import LogWriter
from data_schemas.outputs import OutputGuard, create_new
from recorder.clock import VirtualClock
from recorder.robot.base import RobotConfig
from recorder.robot.errors import RobotConfigError
from recorder.robot.motion import pulses_for_distance, pulses_for_turn
from replay.cli import cli
from tests.hostile import MAGIC, log_with_chunk, nested_text, run_bslam, session_json
from tests.replay.logfactory import session_doc

ROOT = Path(__file__).resolve().parents[2]
#: A hostile file must not keep a command busy longer than this (s).
HANG_S = 5.0
#: Peak memory a command may use on a hostile file (MiB).
PEAK_MIB = 300


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _one_error(lines: list[str], text: str = "") -> None:
    assert len(lines) == 1 and lines[0].startswith("Error: "), lines
    assert "Traceback" not in lines[0]
    assert text in lines[0], lines


def _only(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


# ------------------------------------------------------------------ races for one output
def test_a_name_taken_meanwhile_is_not_replaced(tmp_path: Path) -> None:
    out = tmp_path / "s.json"
    guard = OutputGuard()
    guard.claim(out)  # free when claimed ...
    taken = pytest.raises(OutputError, match="created by another process meanwhile")
    with taken, guard.writing(out) as stream:
        stream.write(b"mine")
        out.write_bytes(b"theirs")  # ... taken by another process before we finish
    assert out.read_bytes() == b"theirs"
    assert _only(tmp_path) == ["s.json"]  # our temporary file is gone


def test_two_recorders_cannot_share_a_name(tmp_path: Path) -> None:
    log = tmp_path / "run.mcap"
    with create_new(log):
        log.write_bytes(b"first")
        with pytest.raises(OutputError, match="created by another process"), create_new(log):
            log.write_bytes(b"second")  # never reached
    assert log.read_bytes() == b"first"
    with pytest.raises(RuntimeError), create_new(tmp_path / "other.mcap"):
        raise RuntimeError  # failed before writing: no empty file left behind
    assert _only(tmp_path) == ["run.mcap"]


@pytest.mark.slow
def test_two_simulations_racing_for_one_log(tmp_path: Path) -> None:
    args = [sys.executable, "-m", "replay.cli", "simulate", "--scenario", "paper"]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    procs = [
        subprocess.Popen(
            [*args, "--out", "run.mcap", "--seed", str(seed)],
            cwd=tmp_path,
            env=env,
            stderr=subprocess.PIPE,
            stdout=subprocess.DEVNULL,
            text=True,
        )
        for seed in (1, 2)
    ]
    results = [(p.wait(timeout=120), p.stderr.read() if p.stderr else "") for p in procs]
    codes = sorted(code for code, _ in results)
    assert codes == [0, 1], results
    loser = next(err for code, err in results if code == 1)
    assert "exists" in loser or "another process" in loser, loser
    with (tmp_path / "run.mcap").open("rb") as f:  # the winner's log, whole and finished
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count > 0


# ------------------------------------------------------------------ full disk
@pytest.mark.parametrize(
    ("command", "outputs"),
    [
        pytest.param(
            ["process", "{log}", "--out", "d.mcap", "--summary", "s.json"],
            ["d.mcap", "s.json"],
            marks=pytest.mark.slow,
        ),
        (["recover", "{log}", "r.mcap"], ["r.mcap"]),
    ],
)
def test_a_full_disk_is_one_line_and_leaves_nothing(
    small_log: Path, tmp_path: Path, command: list[str], outputs: list[str]
) -> None:
    before = _digest(small_log)
    args = [a.format(log=small_log) for a in command]
    code, lines, _ = run_bslam(*args, limit=4000, cwd=tmp_path)
    assert code == 1
    _one_error(lines, "cannot write")
    assert _only(tmp_path) == []  # no output, no temporary file
    assert _digest(small_log) == before


@pytest.mark.slow
def test_a_full_disk_under_the_rerun_recording(small_log: Path, tmp_path: Path) -> None:
    code, lines, _ = run_bslam("replay", small_log, "--save", "r.rrd", limit=60_000, cwd=tmp_path)
    assert code == 1
    _one_error(lines, "cannot write")
    assert _only(tmp_path) == []


# ------------------------------------------------------------------ bombs and lies
@pytest.fixture(scope="module")
def session(small_log: Path) -> str:
    return session_json(small_log)


@pytest.mark.parametrize("compression", ["zstd", pytest.param("lz4", marks=pytest.mark.slow)])
def test_a_chunk_of_zeros_is_refused_quickly_in_little_memory(
    session: str, tmp_path: Path, compression: str
) -> None:
    # a small file (zstd: 2 KB, lz4: 200 KB) whose chunk inflates to 48 MiB of zeros (empty
    # records, opcode 0)
    bomb = log_with_chunk(
        tmp_path / "bomb.mcap", session, b"{}", compression=compression, raw=bytes(48 << 20)
    )
    assert bomb.stat().st_size < 256 * 1024
    for command in ("info", "process"):
        start = time.monotonic()
        code, lines, peak = run_bslam(command, bomb)
        assert time.monotonic() - start < HANG_S + 5  # start-up included
        assert code == 1
        _one_error(lines, "inside a chunk")
        assert peak <= PEAK_MIB


def test_a_chunk_that_states_a_huge_size_is_refused(session: str, tmp_path: Path) -> None:
    liar = log_with_chunk(tmp_path / "liar.mcap", session, b"{}", declared=3 << 30)
    code, lines, peak = run_bslam("info", liar)
    assert code == 1
    _one_error(lines, "corrupt")
    assert peak <= PEAK_MIB


def test_decompression_never_exceeds_the_stated_size() -> None:
    import lz4.frame
    import zstandard

    data = bytes(1 << 20)
    streamed = zstandard.ZstdCompressor(write_content_size=False).compress(data)
    with pytest.raises(DecompressionError):  # says 1000, holds a MiB, no size in the frame
        decompress("zstd", streamed, 1000)
    with pytest.raises(DecompressionError):  # the frame's own size disagrees
        decompress("zstd", zstandard.ZstdCompressor().compress(data), 1000)
    with pytest.raises(DecompressionError):
        decompress("lz4", lz4.frame.compress(data), 1000)
    with pytest.raises(DecompressionError, match="over the limit"):
        decompress("zstd", streamed, MAX_CHUNK_BYTES + 1)
    assert decompress("lz4", lz4.frame.compress(data), len(data)) == data
    assert decompress("zstd", streamed, len(data)) == data


# ------------------------------------------------------------------ nesting and numbers
def _scenario(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "s.json"
    path.write_text(text)
    return path


def test_deep_nesting_is_one_line_everywhere(session: str, tmp_path: Path) -> None:
    runner = CliRunner()
    deep_scenario = _scenario(tmp_path, nested_text(100_000))
    result = runner.invoke(cli, ["simulate", "--scenario", str(deep_scenario), "--out", "x"])
    assert result.exit_code == 1 and "nests deeper than" in result.output, result.output
    deep_session = log_with_chunk(tmp_path / "meta.mcap", nested_text(100_000), b"{}")
    for command in ("info", "process"):
        result = runner.invoke(cli, [command, str(deep_session)])
        assert result.exception is None or isinstance(result.exception, SystemExit)
        assert "RecursionError" not in result.output
    message = log_with_chunk(
        tmp_path / "msg.mcap",
        session,
        nested_text(100_000).encode(),
        topic="/robot/movement",
        schema="bslam.Movement",
    )
    result = runner.invoke(cli, ["process", str(message)])
    assert result.exit_code == 1 and "nests deeper than 64" in result.output, result.output
    assert not (tmp_path / "x").exists()


def test_a_huge_movement_index_never_reaches_gtsam(session: str, tmp_path: Path) -> None:
    movement = {
        "timestamp": {"sec": 0, "nsec": 1},
        "index": 10**30,
        "phase": "start",
        "keyframe_timestamp": {"sec": 0, "nsec": 1},
        "turn_rad": 0.0,
        "distance_m": 0.1,
    }
    log = log_with_chunk(
        tmp_path / "big.mcap",
        session,
        json.dumps(movement).encode(),
        topic="/robot/movement",
        schema="bslam.Movement",
    )
    result = CliRunner().invoke(cli, ["process", str(log), "--estimator", "joint"])
    assert result.exit_code == 1, result.output
    assert "field 'index' should be in [0, 2147483647], got a 31-digit number" in result.output


@pytest.mark.parametrize(
    ("key", "value"),
    [("bearing_noise_deg", 1e308), ("pixel_noise", 1e308)],
)
def test_absurd_camera_noise_is_refused_at_entry(tmp_path: Path, key: str, value: float) -> None:
    from recorder.sim.scenario import BUILTIN_SCENARIOS  # noqa: F401 (the paper's exists)

    doc = json.loads((ROOT / "recorder" / "sim" / "scenarios" / "paper.json").read_text())
    doc["camera"][key] = value
    path = _scenario(tmp_path, json.dumps(doc))
    result = CliRunner().invoke(cli, ["simulate", "--scenario", str(path), "--out", "x.mcap"])
    assert result.exit_code == 1 and "maximum" in result.output, result.output
    assert not (tmp_path / "x.mcap").exists()


def test_record_refuses_an_absurd_distance_before_any_log(tmp_path: Path) -> None:
    out = tmp_path / "run.mcap"
    args = ["record", "--port", "x", "--camera", "0", "--out", str(out)]
    args += ["--calibration", "c.json", "--landmarks", "l.json", "--distance", "1e308"]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 2 and "MAX <= 100 m" in result.output, result.output
    assert not out.exists()


def test_a_move_the_robot_cannot_count_is_refused() -> None:
    config = RobotConfig(port="sim", mm_per_pulse=0.08)
    assert pulses_for_distance(config, 1.0) == 12_500  # 1000 mm / 0.08 mm
    for distance_m in (1e308, math.inf, math.nan, 0.08e-3 * 2**31):
        with pytest.raises(RobotConfigError, match="beyond the robot's counter"):
            pulses_for_distance(config, distance_m)
    with pytest.raises(RobotConfigError):
        pulses_for_turn(RobotConfig(port="sim", mm_per_pulse=1e-300), 1.0)


# ------------------------------------------------------------------ special files
@pytest.fixture()
def fifo(tmp_path: Path) -> Iterator[Path]:
    path = tmp_path / "pipe.mcap"
    os.mkfifo(path)
    yield path


def test_a_fifo_is_refused_at_once(fifo: Path, tmp_path: Path) -> None:
    runner = CliRunner()
    for args in (["info"], ["process"], ["recover", "--force"]):
        extra = [str(tmp_path / "r.mcap")] if args[0] == "recover" else []
        start = time.monotonic()
        result = runner.invoke(cli, [args[0], str(fifo), *extra, *args[1:]])
        assert time.monotonic() - start < HANG_S
        assert result.exit_code == 1
        assert "is a FIFO, not a regular file" in result.output, result.output
    for device in ("/dev/zero",):
        result = runner.invoke(cli, ["simulate", "--scenario", device, "--out", "x.mcap"])
        assert result.exit_code == 1 and "character device" in result.output, result.output


@pytest.mark.slow
def test_follow_gives_up_on_a_fifo_after_its_idle_timeout(fifo: Path) -> None:
    start = time.monotonic()
    code, lines, _ = run_bslam("process", "--follow", "--idle-timeout", "1", fifo, timeout=30)
    assert time.monotonic() - start < HANG_S + 5
    assert code == 1
    _one_error(lines, "has not grown for 1 s")


# ------------------------------------------------------------------ links and leftovers
def test_a_dangling_link_is_an_existing_output(small_log: Path, tmp_path: Path) -> None:
    target = tmp_path / "elsewhere" / "s.json"
    target.parent.mkdir()
    link = tmp_path / "s.json"
    link.symlink_to(target)
    runner = CliRunner()
    result = runner.invoke(cli, ["process", str(small_log), "--summary", str(link)])
    assert result.exit_code == 1 and "exists (a symbolic link)" in result.output
    assert not target.exists() and link.is_symlink()
    result = runner.invoke(cli, ["process", str(small_log), "--summary", str(link), "--force"])
    assert result.exit_code == 0, result.output
    assert not target.exists()  # the link is replaced by the file, never written through
    assert not link.is_symlink() and json.loads(link.read_text())["movements"]


@pytest.mark.slow
def test_simulate_onto_a_dangling_link_never_creates_its_target(tmp_path: Path) -> None:
    target = tmp_path / "elsewhere" / "t.mcap"
    link = tmp_path / "run.mcap"
    link.symlink_to(target)
    args = ["simulate", "--scenario", "paper", "--out", str(link)]
    code, lines, _ = run_bslam(*args, cwd=tmp_path, timeout=120)
    assert code == 1
    _one_error(lines, "exists (a symbolic link): pass --force")
    code, lines, _ = run_bslam(*args, "--force", cwd=tmp_path, timeout=120)
    assert code == 0, lines
    assert not target.parent.exists()
    assert (tmp_path / "run.old-1.mcap").is_symlink()  # the link moved aside, as an old log
    assert not link.is_symlink() and link.stat().st_size > 0


def test_stale_temporary_files_are_cleaned(small_log: Path, tmp_path: Path) -> None:
    stale = tmp_path / ".s.json.abcd1234.part.json"
    stale.write_text("left by a killed run")
    old = time.time() - 3600
    os.utime(stale, (old, old))
    live = tmp_path / ".s.json.live0000.part.json"
    live.write_text("another run, still writing")
    os.utime(live, (old, old))
    with live.open("rb") as held:
        fcntl.flock(held.fileno(), fcntl.LOCK_SH)
        result = CliRunner().invoke(
            cli, ["process", str(small_log), "--summary", str(tmp_path / "s.json")]
        )
    assert result.exit_code == 0, result.output
    assert _only(tmp_path) == [".s.json.live0000.part.json", "s.json"]


@pytest.mark.parametrize("mask", [0o022, 0o077])
def test_outputs_follow_the_umask(small_log: Path, tmp_path: Path, mask: int) -> None:
    previous = os.umask(mask)
    try:
        result = CliRunner().invoke(
            cli, ["process", str(small_log), "--summary", str(tmp_path / "s.json")]
        )
    finally:
        os.umask(previous)
    assert result.exit_code == 0, result.output
    assert stat.S_IMODE((tmp_path / "s.json").stat().st_mode) == 0o666 & ~mask


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux's /proc")
@pytest.mark.slow  # the experiment command loads matplotlib and Dask
def test_an_experiment_folder_that_cannot_be_made_is_one_line(tmp_path: Path) -> None:
    too_long = tmp_path.joinpath(*["d" * 200] * 25)  # over PATH_MAX (4096)
    for out in (Path("/proc/no_folder_here"), too_long):
        result = CliRunner().invoke(cli, ["experiment", "paper", "--out", str(out), "--runs", "1"])
        assert result.exit_code == 1, result.output
        assert result.output.startswith("Error: --out: cannot make the folder"), result.output
        assert result.output.count("\n") == 1 and len(result.output) < 400


# ------------------------------------------------------------------ a log being recorded
def test_info_on_a_log_being_recorded(tmp_path: Path) -> None:
    log = tmp_path / "run.mcap"
    writer = LogWriter(log, session_doc(), clock=VirtualClock())
    try:
        writer.flush()
        result = CliRunner().invoke(cli, ["info", str(log)])
    finally:
        writer.finish()
    assert result.exit_code == 0, result.output
    assert f"{log.name}: being recorded" in result.output
    assert "--follow" in result.output
    result = CliRunner().invoke(cli, ["info", str(log)])  # finished now
    assert result.exit_code == 0 and "being recorded" not in result.output


# ------------------------------------------------------------------ recover
def test_recover_refuses_a_file_of_magic_bytes(tmp_path: Path) -> None:
    magic = tmp_path / "magic.mcap"
    magic.write_bytes(MAGIC)
    result = CliRunner().invoke(cli, ["recover", str(magic), str(tmp_path / "r.mcap")])
    assert result.exit_code == 1 and "nothing readable" in result.output, result.output
    assert _only(tmp_path) == ["magic.mcap"]


def test_every_command_counts_salvage_the_same(small_log: Path, tmp_path: Path) -> None:
    data = bytearray(small_log.read_bytes())
    frame = data.index(b'"data":"iVBOR')  # a PNG frame's base64 text, inside a message
    data[frame + 200] ^= 0xFF  # not UTF-8 any more: that one message cannot decode
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(bytes(data))
    with small_log.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None
    total = summary.statistics.message_count  # one chunk in this log: all its messages
    runner = CliRunner()
    said = [
        runner.invoke(cli, ["info", "--check", str(broken)]).output,
        runner.invoke(cli, ["process", str(broken)]).output,
        runner.invoke(cli, ["recover", str(broken), str(tmp_path / "r.mcap")]).output,
    ]
    expected = f"{total - 1} of {total} messages salvaged (1 more dropped"
    assert all(expected in text for text in said), said


def test_skip_corrupt_skips_a_message_that_does_not_decode(small_log: Path, tmp_path: Path) -> None:
    data = bytearray(small_log.read_bytes())
    movement = data.index(b'"phase":"start"')  # a /robot/movement message's data
    start = data.rindex(b'{"timestamp":{"sec"', 0, movement)
    data[start : start + 1] = b"["  # the same length, no longer JSON
    with small_log.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and len(summary.chunk_indexes) == 1
    chunk = summary.chunk_indexes[0]
    # the stored chunk's CRC made anew (zlib), so the damage is in the message alone
    head = chunk.chunk_start_offset + 9 + 16  # opcode, length, start and end time
    size = int.from_bytes(data[head : head + 8], "little")
    records_at = chunk.chunk_start_offset + chunk.chunk_length - size
    crc = zlib.crc32(data[records_at : records_at + size])
    data[head + 8 : head + 12] = crc.to_bytes(4, "little")
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(bytes(data))
    runner = CliRunner()
    result = runner.invoke(cli, ["info", str(broken)])
    assert result.exit_code == 0, result.output  # every chunk checks out
    result = runner.invoke(cli, ["process", str(broken)])
    assert result.exit_code == 1 and "not valid JSON" in result.stderr, result.output
    assert result.stderr.count("\n") == 1
    result = runner.invoke(cli, ["process", str(broken), "--skip-corrupt"])
    assert result.exit_code == 0, result.output
    skipped = [line for line in result.stderr.splitlines() if "does not decode" in line]
    assert len(skipped) == 1 and skipped[0].startswith("warning: "), result.stderr


# ------------------------------------------------------------------ signals at start-up
# (earlier than ~0.2 s the interpreter itself is starting: Python's own start-up, not ours)
@pytest.mark.parametrize(
    ("signum", "delay_s"),
    [(signal.SIGTERM, 0.4)]
    + [
        pytest.param(signum, delay_s, marks=pytest.mark.slow)
        for signum in (signal.SIGTERM, signal.SIGINT)
        for delay_s in (0.4, 0.9, 1.6)
        if (signum, delay_s) != (signal.SIGTERM, 0.4)
    ],
)
def test_a_stop_during_start_up_is_clean(
    small_log: Path, tmp_path: Path, signum: int, delay_s: float
) -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "replay.cli", "process", str(small_log), "--estimator", "joint"],
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    time.sleep(delay_s)
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=HANG_S * 2)
    assert "Traceback" not in err, err
    if proc.returncode != 0:  # 0: it finished before the signal came
        assert proc.returncode == 128 + signum, err
        assert len(err.strip().splitlines()) == 1, err
