"""Following a growing MCAP log: the session, then whole chunks only; waits, ends on the footer
or the idle time-out."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest
from mcap.records import Channel, Schema

from data_schemas.errors import LogError, NotMcapError
from data_schemas.mcap.chunks import McapChunkWriter
from data_schemas.mcap.follow import FollowedLog
from data_schemas.mcap.layout import MAGIC
from tests.mcap_reader import LogReader

SOURCE = Path(__file__).parents[1] / "data" / "regress" / "occluded.mcap"


@pytest.fixture(scope="module")
def log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A stored simulated log rewritten with a chunk every 12 messages, as a slow recorder does."""
    out = tmp_path_factory.mktemp("follow") / "chunked.mcap"
    with LogReader(SOURCE) as reader, out.open("wb") as f:
        writer = McapChunkWriter(f, library="test")
        writer.start(reader.metadata)
        for record in reader.raw_records():
            if isinstance(record, Schema):
                writer.add_schema(record.name, record.encoding, record.data)
            elif isinstance(record, Channel):
                writer.add_channel(record.topic, record.message_encoding, record.schema_id)
            else:
                writer.add_message(
                    record.channel_id,
                    record.sequence,
                    record.log_time,
                    record.publish_time,
                    [record.data],
                )
                if writer.pending_messages == 12:
                    writer.close_chunk()
        writer.finish()
    return out


def _offline(path: Path) -> list[tuple[str, int, int, bytes]]:
    with LogReader(path, allow_unfinished=True) as reader:
        return [(m.topic, m.log_time_ns, m.sequence, m.data) for m in reader.messages()]


def _followed(follower: FollowedLog) -> list[tuple[str, int, int, bytes]]:
    return [(m.topic, m.log_time_ns, m.sequence, m.data) for m in follower.messages()]


def _chunk_ends(path: Path) -> list[int]:
    """File offsets just after each chunk record (where a recorder's write would stop)."""
    data = path.read_bytes()
    pos, ends = len(MAGIC), []
    while pos + 9 <= len(data):
        opcode, length = int(data[pos]), int.from_bytes(data[pos + 1 : pos + 9], "little")
        if opcode == 0x02:  # footer
            break
        pos += 9 + length
        if opcode == 0x06:  # chunk
            ends.append(pos)
    return ends


def test_finished_log_gives_every_message_and_ends_finished(log: Path) -> None:
    with FollowedLog(log, idle_timeout_s=5) as follower:
        assert "bslam.session" in follower.metadata
        assert _followed(follower) == _offline(log)
        assert follower.end == "finished"
        assert "finished" in follower.end_line


def test_growing_file_with_partial_chunks_is_followed_to_the_footer(
    log: Path, tmp_path: Path
) -> None:
    data = log.read_bytes()
    ends = _chunk_ends(log)
    assert len(ends) >= 3
    # grow the copy in pieces that cut chunks in the middle, as a slow write would look
    cuts = sorted({5, ends[0] - 7, ends[0] + 3, (ends[1] + ends[2]) // 2, ends[-1], len(data)})
    out = tmp_path / "growing.mcap"

    def grow() -> None:
        time.sleep(0.15)  # the follower starts before the file exists
        with out.open("wb") as f:
            last = 0
            for cut in cuts:
                f.write(data[last:cut])
                f.flush()
                last = cut
                time.sleep(0.1)

    writer = threading.Thread(target=grow)
    writer.start()
    try:
        with FollowedLog(out, idle_timeout_s=3, poll_s=0.01) as follower:
            got = _followed(follower)
            assert follower.end == "finished"
    finally:
        writer.join()
    assert got == _offline(log)


def test_unfinished_log_ends_after_idle_timeout_with_a_clear_line(
    log: Path, tmp_path: Path
) -> None:
    ends = _chunk_ends(log)
    out = tmp_path / "killed.mcap"
    out.write_bytes(log.read_bytes()[: ends[1] + 11])  # two chunks and a torn third
    t0 = time.monotonic()
    with FollowedLog(out, idle_timeout_s=0.4, poll_s=0.01) as follower:
        got = _followed(follower)
    waited = time.monotonic() - t0
    assert follower.end == "idle"
    assert follower.chunk_count == 2
    assert "has not grown for 0.4 s" in follower.end_line and "recover" in follower.end_line
    assert got == _offline(out) and got
    assert waited >= 0.4


def test_missing_file_times_out(tmp_path: Path) -> None:
    with pytest.raises(LogError, match=r"did not appear within 0\.2 s"):
        FollowedLog(tmp_path / "none.mcap", idle_timeout_s=0.2, poll_s=0.01)


def test_not_mcap_and_empty_logs(tmp_path: Path) -> None:
    text = tmp_path / "text.mcap"
    text.write_text("hello, this is not a log\n")
    with pytest.raises(NotMcapError):
        FollowedLog(text, idle_timeout_s=0.2)
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    with pytest.raises(LogError, match=r"has not grown for 0\.2 s.*no session yet"):
        FollowedLog(empty, idle_timeout_s=0.2, poll_s=0.01)


def test_damaged_chunk_is_reported_after_the_good_ones(log: Path, tmp_path: Path) -> None:
    ends = _chunk_ends(log)
    data = bytearray(log.read_bytes())
    data[ends[1] - 20] ^= 0xFF  # a byte inside the second chunk's records: CRC mismatch
    out = tmp_path / "damaged.mcap"
    out.write_bytes(bytes(data))
    follower = FollowedLog(out, idle_timeout_s=0.5)
    got = []
    with pytest.raises(LogError, match=r"chunk at byte \d+ is damaged"):
        for message in follower.messages():
            got.append(message)
    assert follower.chunk_count == 1 and got


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_chunks_of_another_writer_are_followed(log: Path, tmp_path: Path, compression: str) -> None:
    # mcap's own Writer: small chunks, compressed or not, schemas and channels in the chunks
    from mcap.writer import CompressionType, Writer

    out = tmp_path / f"{compression}.mcap"
    with LogReader(SOURCE) as reader, out.open("wb") as f:
        writer = Writer(f, chunk_size=2000, compression=CompressionType[compression.upper()])
        writer.start()
        for name, values in reader.metadata.items():
            writer.add_metadata(name, values)
        schema_ids: dict[int, int] = {}
        channel_ids: dict[int, int] = {}
        for record in reader.raw_records():
            if isinstance(record, Schema):
                schema_ids[record.id] = writer.register_schema(
                    record.name, record.encoding, record.data
                )
            elif isinstance(record, Channel):
                channel_ids[record.id] = writer.register_channel(
                    record.topic, record.message_encoding, schema_ids[record.schema_id]
                )
            else:
                writer.add_message(
                    channel_ids[record.channel_id],
                    log_time=record.log_time,
                    data=record.data,
                    publish_time=record.publish_time,
                    sequence=record.sequence,
                )
        writer.finish()
    with FollowedLog(out, idle_timeout_s=1) as follower:
        got = _followed(follower)
        assert follower.end == "finished" and follower.chunk_count > 3
    assert got == _offline(SOURCE) and got
