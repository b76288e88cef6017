"""recover keeps every message whose record is on disk whole: cuts and flipped bytes anywhere."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from mcap.reader import make_reader

from data_schemas.errors import CorruptLogError, LogError
from data_schemas.mcap.info import log_summary
from data_schemas.mcap.processable import ProcessableLog
from data_schemas.mcap.read import LogReader
from data_schemas.mcap.recover import recover_log
from data_schemas.mcap.writer import LogWriter
from recorder.clock import VirtualClock
from recorder.timebase import EpochClock
from replay.cli import cli
from tests.recorder.samples import make_session_doc, sample_messages

Msg = tuple[str, int, int, bytes]  # topic, sequence, log time, data


def _log(path: Path, frames: int, chunk_bytes: int) -> None:
    clock = EpochClock(VirtualClock())
    doc = make_session_doc()
    with LogWriter(path, doc, clock=clock, chunk_bytes=chunk_bytes, fsync=False) as log:
        for i in range(frames):
            msgs = sample_messages(clock.monotonic_ns(), np.random.default_rng(i))
            log.write("/camera/panorama", msgs["/camera/panorama"])
            clock.sleep(0.01)
            log.write("/robot/odometry", msgs["/robot/odometry"])
            clock.sleep(0.01)


@pytest.fixture(scope="module", params=[(40, 10**8), (50, 100)], ids=["1-chunk", "100-chunks"])
def finished(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Path:
    frames, chunk_bytes = request.param
    path = tmp_path_factory.mktemp("logs") / "a.mcap"
    _log(path, frames, chunk_bytes)
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    assert len(summary.chunk_indexes) == (1 if frames == 40 else 100)
    return path


def _messages(path: Path) -> list[Msg]:
    with LogReader(path, allow_unfinished=True, allow_corrupt=True) as reader:
        return [(m.topic, m.sequence, m.log_time_ns, m.data) for m in reader.messages()]


def _spans(path: Path) -> list[tuple[Msg, int, int]]:
    """Every message of a finished log with the file span of its record (start, end)."""
    data = path.read_bytes()
    spans = []
    pos = 0
    for m in _messages(path):
        at = data.find(m[3], pos)
        assert at > 0
        spans.append((m, at - 31, at + len(m[3])))  # 31: opcode, length and message fields
        pos = at
    return spans


def _offsets(size: int, n: int, seed: int) -> list[int]:
    rng = np.random.default_rng(seed)
    spread = np.linspace(8, size - 1, n // 2).astype(int)
    return sorted({*spread.tolist(), *rng.integers(8, size, n - n // 2).tolist()})


def test_cut_anywhere_keeps_every_complete_message(finished: Path, tmp_path: Path) -> None:
    data = finished.read_bytes()
    spans = _spans(finished)
    broken, fixed = tmp_path / "cut.mcap", tmp_path / "fixed.mcap"
    for cut in _offsets(len(data), 80, seed=1):
        broken.write_bytes(data[:cut])
        want = [m for m, _, end in spans if end <= cut]
        if not want and cut < spans[0][1]:
            continue  # nothing to keep: "nothing readable" is covered below
        report = recover_log(broken, fixed, force=True)
        assert report.messages == len(want), cut
        with LogReader(fixed) as reader:
            got = [(m.topic, m.sequence, m.log_time_ns, m.data) for m in reader.messages()]
        assert got == want, cut
        assert reader.metadata == LogReader(finished).metadata


def test_one_flipped_byte_anywhere(finished: Path, tmp_path: Path) -> None:
    data = finished.read_bytes()
    spans = _spans(finished)
    with finished.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    first_chunk = summary.chunk_indexes[0].chunk_start_offset
    broken, fixed = tmp_path / "flip.mcap", tmp_path / "fixed.mcap"
    rng = np.random.default_rng(2)
    for offset in _offsets(len(data), 80, seed=3):
        damaged = bytearray(data)
        damaged[offset] ^= int(rng.integers(1, 256))
        broken.write_bytes(bytes(damaged))
        s = log_summary(broken)  # no traceback, no hang
        if offset >= first_chunk:  # header and metadata strings carry no CRC
            assert s.damage and not s.finished, offset
        report = recover_log(broken, fixed, force=True)
        kept = set(_messages(fixed))
        lost = [m for m, start, end in spans if not start <= offset < end and m not in kept]
        assert lost == [], offset
        if offset >= first_chunk:
            assert report.damage


def test_recover_exit_codes(finished: Path, tmp_path: Path) -> None:
    runner = CliRunner()
    fixed = tmp_path / "fixed.mcap"
    whole = runner.invoke(cli, ["recover", str(finished), str(fixed)])
    assert whole.exit_code == 0, whole.output
    assert "already finished" in whole.output
    data = bytearray(finished.read_bytes())
    spans = _spans(finished)
    middle = spans[len(spans) // 2]
    data[middle[2] - 3] ^= 0x20  # inside a message's JSON: the chunk CRC fails
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(bytes(data))
    lossy = runner.invoke(cli, ["recover", str(broken), str(fixed), "--force"])
    assert lossy.exit_code == 3, lossy.output
    assert "CRC mismatch" in lossy.output and "messages salvaged" in lossy.output
    assert len(_messages(fixed)) == len(spans)  # all complete records kept
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(bytes(data[:8]) + b"\xee" * 500)
    nothing = runner.invoke(cli, ["recover", str(garbage), str(tmp_path / "none.mcap")])
    assert nothing.exit_code == 1 and "nothing readable" in nothing.output
    assert not (tmp_path / "none.mcap").exists()
    with pytest.raises(LogError, match="nothing readable"):
        recover_log(garbage, tmp_path / "none.mcap")


@pytest.mark.parametrize("which", ["first", "middle", "last"])
def test_processable_log_refuses_or_skips_a_corrupt_chunk(
    finished: Path, tmp_path: Path, which: str
) -> None:
    with finished.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    chunks = summary.chunk_indexes
    chunk = {"first": chunks[0], "middle": chunks[len(chunks) // 2], "last": chunks[-1]}[which]
    data = bytearray(finished.read_bytes())
    data[chunk.chunk_start_offset + chunk.chunk_length - 12] ^= 0x01  # in its last message
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(bytes(data))
    with ProcessableLog(finished) as whole:
        everything = [(m.topic, m.log_time_ns, m.data) for m in whole.messages()]
    got: list[tuple[str, int, bytes]] = []
    with (
        ProcessableLog(broken) as log,
        pytest.raises(CorruptLogError, match=r"is corrupt: chunk at bytes .*--skip-corrupt"),
    ):
        got.extend((m.topic, m.log_time_ns, m.data) for m in log.messages())
    # the pass stops where it reaches the damaged chunk, before any of its messages
    inside = [m for m in everything if chunk.message_start_time <= m[1] <= chunk.message_end_time]
    assert got == everything[: len(got)] and not set(got) & set(inside)
    assert (len(got) > 0) == (chunk != chunks[0])
    with ProcessableLog(broken, skip_corrupt=True) as log:
        [skipped] = log.skipped
        assert (skipped.start_ns, skipped.end_ns) == (
            chunk.message_start_time,
            chunk.message_end_time,
        )
        kept = [(m.topic, m.log_time_ns, m.data) for m in log.messages()]
    assert inside and kept == [m for m in everything if m not in inside]
    s = log_summary(broken)
    assert s.state == "corrupt" and [d.start for d in s.damage] == [chunk.chunk_start_offset]
