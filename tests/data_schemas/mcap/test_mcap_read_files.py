"""LogReader, log_summary and recover_log on finished, truncated, corrupt and foreign files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from data_schemas.errors import (
    CorruptLogError,
    LogError,
    MissingMetadataError,
    NotMcapError,
    OutputError,
    UnfinishedLogError,
)
from data_schemas.mcap.info import log_summary
from data_schemas.mcap.recover import recover_log
from data_schemas.mcap.writer import LogWriter
from data_schemas.registry import SESSION_METADATA_NAME
from recorder.clock import VirtualClock
from recorder.timebase import EpochClock
from tests.mcap_reader import LogReader
from tests.recorder.samples import make_session_doc, sample_messages


def _finished_log(path: Path, frames: int = 30) -> None:
    clock = EpochClock(VirtualClock())
    with LogWriter(path, make_session_doc(), clock=clock, chunk_bytes=3000) as log:
        for i in range(frames):
            msgs = sample_messages(clock.monotonic_ns(), np.random.default_rng(i))
            log.write("/camera/panorama", msgs["/camera/panorama"])
            clock.sleep(0.01)
            log.write("/robot/odometry", msgs["/robot/odometry"])
            clock.sleep(0.01)


@pytest.mark.parametrize("check", [False, True])
def test_summary_of_finished_log(tmp_path: Path, check: bool) -> None:
    # from the summary section, or by reading every chunk: the same figures
    path = tmp_path / "a.mcap"
    _finished_log(path, frames=10)
    s = log_summary(path, check=check)
    assert s.finished and s.trailing_bytes == 0 and s.indexed and s.checked == check
    assert [(c.topic, c.schema, c.count) for c in s.channels] == [
        ("/camera/panorama", "foxglove.CompressedImage", 10),
        ("/robot/odometry", "bslam.Odometry", 10),
    ]
    assert s.message_count == 20
    assert s.duration_s == pytest.approx(19 * 0.01)
    assert s.chunk_count >= 1 and s.compressions == ("stored",)
    assert SESSION_METADATA_NAME in s.metadata


@pytest.mark.parametrize("fraction", [0.35, 0.6, 0.93])
def test_truncated_log_reads_every_complete_message(tmp_path: Path, fraction: float) -> None:
    path = tmp_path / "a.mcap"
    _finished_log(path)
    data = path.read_bytes()
    cut = int(len(data) * fraction)
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(data[:cut])
    with LogReader(path) as reader:
        original = [(m.topic, m.log_time_ns, m.data) for m in reader.messages()]
    expected = [m for m in original if data.find(m[2]) + len(m[2]) <= cut]
    assert 0 < len(expected) < len(original)

    readable = rf"unfinished .*: {len(expected)} messages are readable; run `bslam recover"
    with pytest.raises(UnfinishedLogError, match=readable):
        LogReader(broken)
    with LogReader(broken, allow_unfinished=True) as reader:
        assert not reader.finished
        assert reader.session().reference == ("L1", "L2")
        assert [(m.topic, m.log_time_ns, m.data) for m in reader.messages()] == expected

    fixed = tmp_path / "fixed.mcap"
    report = recover_log(broken, fixed)
    assert report.messages == len(expected) and not report.was_finished
    with LogReader(fixed) as reader:  # finished now: no allow_unfinished needed
        assert reader.finished
        assert reader.metadata == log_summary(path).metadata
        assert [(m.topic, m.log_time_ns, m.data) for m in reader.messages()] == expected
    with fixed.open("rb") as f:  # and the index is valid for mcap's own reader
        assert sum(1 for _ in make_reader(f).iter_messages()) == len(expected)


def test_corrupt_chunk_is_refused_then_read_around(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    _finished_log(path)
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    third = summary.chunk_indexes[2]
    data = bytearray(path.read_bytes())
    data[third.chunk_start_offset + third.chunk_length - 10] ^= 0xFF
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(bytes(data))
    with pytest.raises(CorruptLogError, match=r"chunk at bytes \d+-\d+: CRC mismatch, log time"):
        LogReader(broken)
    with LogReader(broken, allow_corrupt=True) as reader:
        n = sum(1 for _ in reader.messages())
        assert reader.chunk_count == len(summary.chunk_indexes) - 1
        assert not reader.finished
    # the flipped byte (10 bytes before the chunk's end) lies in its last message's JSON, where
    # a byte >= 0x80 is not UTF-8: that message is dropped, every other one kept
    assert n == sum(summary.statistics.channel_message_counts.values()) - 1  # type: ignore[union-attr]
    fast = log_summary(broken)  # from the summary section: the chunks are not read
    assert fast.finished and not fast.checked and fast.message_count == n + 1
    s = log_summary(broken, check=True)
    assert s.state == "corrupt" and not s.finished and s.checked
    [damage] = s.damage
    assert damage.dropped == 1 and "1 more dropped" in damage.describe()
    assert (damage.start_ns, damage.end_ns) == (
        third.message_start_time,
        third.message_end_time,
    )
    assert damage.topics == {"/camera/panorama", "/robot/odometry"} or damage.topics


def test_not_mcap(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    path.write_text("hello, I am a text file\n")
    with pytest.raises(NotMcapError, match=r"a.mcap is not an MCAP file"):
        log_summary(path)
    with pytest.raises(LogError, match="cannot open log"):
        log_summary(tmp_path / "missing.mcap")


def test_missing_session_metadata(tmp_path: Path) -> None:
    path = tmp_path / "plain.mcap"
    with path.open("wb") as f:
        w = Writer(f)
        w.start()
        w.finish()
    missing = r"no 'bslam\.session'"
    with LogReader(path) as reader, pytest.raises(MissingMetadataError, match=missing):
        reader.session()


def test_empty_unfinished_log_has_only_metadata(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    log = LogWriter(path, make_session_doc(), clock=VirtualClock())
    try:
        # the session record reaches the file before any message is written
        s = log_summary(path)
        assert not s.finished and s.message_count == 0
        assert SESSION_METADATA_NAME in s.metadata
    finally:
        log.finish()


def test_recover_refuses_to_overwrite_its_input(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    _finished_log(path, frames=2)
    with pytest.raises(OutputError, match="is the input"):
        recover_log(path, path)
