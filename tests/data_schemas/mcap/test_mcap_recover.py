"""recover keeps every message whose record is on disk whole: cuts and flipped bytes anywhere."""

from __future__ import annotations

import io
import struct
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from mcap.exceptions import EndOfFile, McapError
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, McapRecord, Message
from mcap.stream_reader import StreamReader

from data_schemas.errors import CorruptLogError, LogError
from data_schemas.mcap.info import log_summary
from data_schemas.mcap.processable import ProcessableLog
from data_schemas.mcap.recover import recover_log
from data_schemas.mcap.writer import LogWriter
from recorder.clock import VirtualClock
from recorder.timebase import EpochClock
from replay.cli import cli
from tests.mcap_library import chunk_records
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


@pytest.fixture(
    scope="module",
    params=[(40, 10**8), (50, 100), (50, 6000)],
    ids=["1-chunk", "1-message-chunks", "several-message-chunks"],
)
def finished(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Path:
    frames, chunk_bytes = request.param
    path = tmp_path_factory.mktemp("logs") / "a.mcap"
    _log(path, frames, chunk_bytes)
    chunks = [r for r, _ in _library_records(path.read_bytes()) if isinstance(r, Chunk)]
    sizes = [sum(isinstance(r, Message) for r in chunk_records(c)) for c in chunks]
    if chunk_bytes == 10**8:
        assert sizes == [2 * frames]
    elif chunk_bytes == 100:
        assert sizes == [1] * (2 * frames)
    else:  # a cut inside a chunk leaves whole messages before it
        assert len(sizes) >= 5 and min(sizes[:-1]) >= 3
    return path


def _library_records(data: bytes) -> Iterator[tuple[McapRecord, int]]:
    """The records the mcap library reads whole from ``data``, each with its end offset."""
    stream = io.BytesIO(data)
    try:
        for record in StreamReader(stream, emit_chunks=True, validate_crcs=True).records:
            yield record, stream.tell()
    except (EndOfFile, struct.error):
        return


def _read_until_damage(data: bytes) -> list[Msg]:
    """The messages the mcap library reads, CRCs checked, from damaged bytes until it stops."""
    topics: dict[int, str] = {}
    out: list[Msg] = []
    stream = io.BytesIO(data)
    try:
        for record in StreamReader(stream, emit_chunks=True, validate_crcs=True).records:
            inner = chunk_records(record) if isinstance(record, Chunk) else [record]
            for rec in inner:
                if isinstance(rec, Channel):
                    topics[rec.id] = rec.topic
                elif isinstance(rec, Message):
                    out.append((topics[rec.channel_id], rec.sequence, rec.log_time, rec.data))
    except (McapError, ValueError, struct.error, KeyError, UnicodeDecodeError):
        pass  # the library stops at the damage; what it read before counts
    return out


def _spans(data: bytes) -> list[tuple[Msg, int, int]]:
    """Every message the mcap library reads from ``data``, with its record's file span.

    A stored chunk's records are its record's last field: they end where the chunk ends, and
    each inside is opcode (1 byte), length (8 bytes), content (the MCAP specification).
    """
    topics: dict[int, str] = {}
    out: list[tuple[Msg, int, int]] = []
    for record, end in _library_records(data):
        assert not isinstance(record, Message)  # the recorder writes every message in a chunk
        if isinstance(record, Channel):
            topics[record.id] = record.topic
        if not isinstance(record, Chunk):
            continue
        assert record.compression == ""
        base = end - len(record.data)
        inner = iter(chunk_records(record))
        pos = 0
        while pos < len(record.data):
            opcode, length = struct.unpack_from("<BQ", record.data, pos)
            stop = pos + 9 + length
            if opcode in (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.MESSAGE):
                rec = next(inner)
                if isinstance(rec, Channel):
                    topics[rec.id] = rec.topic
                elif isinstance(rec, Message):
                    msg = (topics[rec.channel_id], rec.sequence, rec.log_time, rec.data)
                    assert data[base + stop - len(rec.data) : base + stop] == rec.data
                    out.append((msg, base + pos, base + stop))
            pos = stop
    return out


def _metadata(path: Path) -> list[tuple[str, dict[str, str]]]:
    with path.open("rb") as f:
        return [(m.name, dict(m.metadata)) for m in make_reader(f).iter_metadata()]


def _messages(path: Path) -> list[Msg]:
    """The messages of a finished log as the mcap library reads them (CRCs checked)."""
    with path.open("rb") as f:
        reader = make_reader(f, validate_crcs=True)
        return [
            (channel.topic, m.sequence, m.log_time, m.data)
            for _, channel, m in reader.iter_messages(log_time_order=False)
        ]


def _offsets(size: int, n: int, seed: int) -> list[int]:
    rng = np.random.default_rng(seed)
    spread = np.linspace(8, size - 1, n // 2).astype(int)
    return sorted({*spread.tolist(), *rng.integers(8, size, n - n // 2).tolist()})


def test_cut_anywhere_keeps_every_complete_message(finished: Path, tmp_path: Path) -> None:
    data = finished.read_bytes()
    spans = _spans(data)
    assert [m for m, _, _ in spans] == _messages(finished)
    broken, fixed = tmp_path / "cut.mcap", tmp_path / "fixed.mcap"
    for cut in _offsets(len(data), 48, seed=1):
        broken.write_bytes(data[:cut])
        want = [m for m, _, end in spans if end <= cut]
        # the chunks the library itself reads whole from the cut bytes come first
        whole = [m for m, _, _ in _spans(data[:cut])]
        assert want[: len(whole)] == whole, cut
        if not want and cut < spans[0][1]:
            continue  # nothing to keep: "nothing readable" is covered below
        report = recover_log(broken, fixed, force=True)
        assert report.messages == len(want), cut
        assert _messages(fixed) == want, cut
        assert _metadata(fixed) == _metadata(finished)


def test_one_flipped_byte_anywhere(finished: Path, tmp_path: Path) -> None:
    data = finished.read_bytes()
    spans = _spans(data)
    with finished.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    first_chunk = summary.chunk_indexes[0].chunk_start_offset
    broken, fixed = tmp_path / "flip.mcap", tmp_path / "fixed.mcap"
    rng = np.random.default_rng(2)
    for offset in _offsets(len(data), 48, seed=3):
        damaged = bytearray(data)
        damaged[offset] ^= int(rng.integers(1, 256))
        broken.write_bytes(bytes(damaged))
        s = log_summary(broken, check=True)  # no traceback, no hang
        if offset >= first_chunk:  # header and metadata strings carry no CRC
            assert s.damage and not s.finished, offset
        report = recover_log(broken, fixed, force=True)
        got = _messages(fixed)
        assert report.messages == len(got), offset
        # every message whose record the flip missed comes back (those salvaged from a damaged
        # chunk in another order); the one it hit (if any) comes back changed or not at all
        others = [m for m, start, end in spans if not start <= offset < end]
        assert sorted(m for m in got if m in set(others)) == sorted(others), offset
        # and whatever the library itself reads from the damaged bytes is among them
        library = _read_until_damage(bytes(damaged))
        assert len(set(library) - set(got)) == 0 and len(library) <= len(got), offset
        assert len(others) <= len(got) <= len(spans), offset
        if offset >= first_chunk:
            assert report.damage


def test_recover_exit_codes(finished: Path, tmp_path: Path) -> None:
    runner = CliRunner()
    fixed = tmp_path / "fixed.mcap"
    whole = runner.invoke(cli, ["recover", str(finished), str(fixed)])
    assert whole.exit_code == 0, whole.output
    assert "already finished" in whole.output
    data = bytearray(finished.read_bytes())
    spans = _spans(bytes(data))
    middle = spans[len(spans) // 2]
    data[middle[2] - 3] ^= 0x20  # inside a message's JSON: the chunk CRC fails
    topic, sequence, log_time, payload = middle[0]
    changed = (topic, sequence, log_time, payload[:-3] + bytes([payload[-3] ^ 0x20]) + payload[-2:])
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(bytes(data))
    lossy = runner.invoke(cli, ["recover", str(broken), str(fixed), "--force"])
    assert lossy.exit_code == 3, lossy.output
    assert "CRC mismatch" in lossy.output and "messages salvaged" in lossy.output
    # all complete records kept, the damaged one as it now is
    assert _messages(fixed) == [changed if s is middle else s[0] for s in spans]
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
    s = log_summary(broken, check=True)
    assert s.state == "corrupt" and [d.start for d in s.damage] == [chunk.chunk_start_offset]
