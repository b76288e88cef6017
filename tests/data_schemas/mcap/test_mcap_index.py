"""LogIndex reads messages in place and gives exactly what mcap's indexed reader gives."""

from __future__ import annotations

import inspect
import io
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import SeekingReader, make_reader
from mcap.writer import CompressionType, IndexType, Writer

from data_schemas.mcap.chunks import McapChunkWriter
from data_schemas.mcap.index import CorruptChunksError, DamagedLogError, LogIndex
from data_schemas.mcap.layout import MESSAGE_HEADER


def _recorded(seed: int = 3) -> bytes:
    """Three channels over four stored chunks: log times out of order inside a chunk, ties
    between channels and chunks, time ranges of chunks overlapping, one channel absent from a
    chunk, empty and large payloads."""
    rng = np.random.default_rng(seed)
    out = io.BytesIO()
    mcap = McapChunkWriter(out, library="test")
    mcap.start({})
    schema = mcap.add_schema("s", "jsonschema", b"{}")
    channels = [mcap.add_channel(t, "json", schema) for t in ("/a", "/b", "/c")]
    seq = 0
    for chunk in range(4):
        for _ in range(25):
            channel = int(rng.integers(0, 3 if chunk != 2 else 2))
            t_ns = 1000 + 10 * int(rng.integers(0, 40))  # ties in and across chunks
            seq += 1
            data = rng.bytes(int(rng.choice([0, 5, 70_000])))
            mcap.add_message(channels[channel], seq, t_ns, t_ns + seq, [data])
        assert mcap.close_chunk()
    mcap.finish()
    return out.getvalue()


def _tuples(messages: Any) -> list[tuple[int, int, int, int, bytes]]:
    """mcap ``Message`` records as the index's field tuples."""
    return [(m.channel_id, m.sequence, m.log_time, m.publish_time, m.data) for m in messages]


def _fields(fields: Any) -> list[tuple[int, int, int, int, bytes]]:
    """The index's field tuples, data as bytes."""
    return [(c, seq, t, pt, bytes(data)) for c, seq, t, pt, data in fields]


def _index(data: bytes) -> tuple[LogIndex, Any]:
    stream = io.BytesIO(data)
    reader = make_reader(stream)
    index = LogIndex.of(stream, reader.get_summary())
    assert index is not None
    return index, reader


@pytest.mark.parametrize(
    ("topics", "bounds"),
    [
        (["/a", "/b", "/c"], (None, None)),
        (["/b"], (None, None)),
        (["/a", "/c"], (5, 20)),  # log times of their 5th and 20th message: [start, end)
        (["/c"], (12, None)),
        (["/a"], (None, 0)),
    ],
)
def test_same_messages_and_order_as_mcap(
    topics: list[str], bounds: tuple[int | None, int | None]
) -> None:
    index, reader = _index(_recorded())
    times = [m.log_time for _, _, m in reader.iter_messages(topics, log_time_order=True)]
    start_ns, end_ns = (None if k is None else times[k] for k in bounds)
    ids = [i for i, c in reader.get_summary().channels.items() if c.topic in topics]
    expected = _tuples(
        m
        for _, _, m in reader.iter_messages(topics, log_time_order=True, **_range(start_ns, end_ns))
    )
    got = _fields(index.fields(ids, start_ns=start_ns, end_ns=end_ns))
    assert got == expected
    assert len(got) > 0 or bounds == (None, 0)
    if start_ns is not None:
        assert got[0][2] == start_ns  # the start bound is inclusive


def test_publish_time_filter_keeps_only_those() -> None:
    index, reader = _index(_recorded())
    everything = _fields(index.fields(list(reader.get_summary().channels)))
    chosen = {everything[i][3] for i in (0, 7, 40)}
    got = _fields(index.fields(list(reader.get_summary().channels), publish_times_ns=chosen))
    assert got == [m for m in everything if m[3] in chosen]


def test_unindexed_logs_are_left_to_the_scan() -> None:
    out = io.BytesIO()
    writer = Writer(out, index_types=IndexType.ALL & ~IndexType.MESSAGE)
    writer.start()
    schema = writer.register_schema("s", "jsonschema", b"{}")
    channel = writer.register_channel("/a", "json", schema)
    writer.add_message(channel, 1, b"{}", 1)
    writer.finish()
    out.seek(0)
    assert LogIndex.of(out, make_reader(out).get_summary()) is None


def _rewritten(data: bytes, compression: CompressionType, chunk_size: int = 60_000) -> bytes:
    """``data`` written again by mcap's ``Writer`` with compressed chunks."""
    out = io.BytesIO()
    writer = Writer(out, compression=compression, chunk_size=chunk_size)
    writer.start()
    reader = make_reader(io.BytesIO(data))
    ids: dict[int, int] = {}
    for schema, channel, message in reader.iter_messages():
        if channel.id not in ids:
            sid = writer.register_schema(schema.name, schema.encoding, schema.data)
            ids[channel.id] = writer.register_channel(channel.topic, "json", sid)
        writer.add_message(
            ids[channel.id], message.log_time, message.data, message.publish_time, message.sequence
        )
    writer.finish()
    return out.getvalue()


@pytest.mark.parametrize("compression", [CompressionType.ZSTD, CompressionType.LZ4])
def test_compressed_log_gives_what_mcap_gives(compression: CompressionType) -> None:
    data = _rewritten(_recorded(), compression)
    index, reader = _index(data)
    assert len(reader.get_summary().chunk_indexes) > 4  # several compressed chunks
    assert {c.compression for c in reader.get_summary().chunk_indexes} == {compression.name.lower()}
    ids = list(reader.get_summary().channels)
    for topics in (["/a", "/b", "/c"], ["/b"]):
        chosen = [i for i in ids if reader.get_summary().channels[i].topic in topics]
        expected = _tuples(m for _, _, m in reader.iter_messages(topics, log_time_order=True))
        assert _fields(index.fields(chosen)) == expected
    everything = _fields(index.fields(ids))
    chosen_times = {everything[i][3] for i in (1, 30, 99)}
    assert _fields(index.fields(ids, publish_times_ns=chosen_times)) == [
        m for m in everything if m[3] in chosen_times
    ]


@pytest.mark.parametrize("compression", [CompressionType.NONE, CompressionType.ZSTD])
def test_damaged_chunk_is_refused_before_any_of_its_messages(compression: CompressionType) -> None:
    """One byte changed in the third of several chunks: the messages of the chunks before it
    are read, then the pass stops; nothing of the damaged chunk comes out."""
    clean = (
        _recorded() if compression == CompressionType.NONE else _rewritten(_recorded(), compression)
    )
    summary = make_reader(io.BytesIO(clean)).get_summary()
    assert summary is not None
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    target = chunks[2]
    data = bytearray(clean)
    at = target.chunk_start_offset + target.chunk_length - 40  # inside its last record
    data[at] ^= 0x10
    index, _ = _index(bytes(data))
    channels = list(summary.channels)
    got: list[Any] = []
    with pytest.raises(CorruptChunksError, match=rf"chunk at byte {target.chunk_start_offset}: "):
        got.extend(index.fields(channels))
    assert got  # the chunks before it were read
    clean_index, _ = _index(clean)
    loaded = clean_index._load(target.chunk_start_offset)
    assert loaded.problem == ""
    inside = {
        loaded.message(  # type: ignore[index]
            clean_index._data(), target.chunk_start_offset, offset, (channel, t), None
        )[1]  # its sequence
        for offset, channel, t in clean_index._entries[target.chunk_start_offset]
    }
    assert inside and not {sequence for _, sequence, *_ in got} & inside
    assert [c for c, _ in index.verify()] == [target]


def test_index_disagreeing_with_an_intact_chunk_is_damage() -> None:
    """The chunk's CRC is fine but its message index lists a log time its message lacks."""
    data = bytearray(_recorded())
    summary = make_reader(io.BytesIO(bytes(data))).get_summary()
    assert summary is not None
    chunk = summary.chunk_indexes[1]
    entry = chunk.message_index_offsets[1] + 9 + 6  # first entry of channel 1's index
    data[entry : entry + 8] = (12_345).to_bytes(8, "little")  # its log time
    index, _ = _index(bytes(data))
    with pytest.raises(CorruptChunksError, match="message index disagrees with its records"):
        list(index.fields(list(summary.channels)))


def test_uncompressed_mcap_writer_log_is_read_in_place() -> None:
    out = io.BytesIO()
    writer = Writer(out, compression=CompressionType.NONE)
    writer.start()
    schema = writer.register_schema("s", "jsonschema", b"{}")
    channel = writer.register_channel("/a", "json", schema)
    for t in (30, 10, 20):
        writer.add_message(channel, t, b'{"t": %d}' % t, t + 1)
    writer.finish()
    index, reader = _index(out.getvalue())
    assert _fields(index.fields([channel])) == _tuples(m for _, _, m in reader.iter_messages())


def _one_chunk() -> bytes:
    out = io.BytesIO()
    mcap = McapChunkWriter(out, library="test")
    mcap.start({})
    channel = mcap.add_channel("/a", "json", mcap.add_schema("s", "jsonschema", b"{}"))
    for n in range(3):
        mcap.add_message(channel, n + 1, 10 * n, 10 * n, [b'{"n": %d}' % n])
    mcap.finish()
    return out.getvalue()


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        (0, b"\x7f", "no message of channel 1"),  # opcode
        (9, (7).to_bytes(2, "little"), "no message of channel 1"),  # channel id
        (15, (11).to_bytes(8, "little"), "no message of channel 1"),  # log time
        (1, (10**6).to_bytes(8, "little"), "cut short"),  # record length past the file
    ],
)
def test_index_not_matching_the_message_is_damage(field: int, value: bytes, match: str) -> None:
    data = bytearray(_one_chunk())
    record = data.index(b'{"n": 1}') - MESSAGE_HEADER.size
    data[record + field : record + field + len(value)] = value
    index, _ = _index(bytes(data))
    # the chunk check sees it first (before any message), then the read itself would
    with pytest.raises(CorruptChunksError, match=r"chunk at byte \d+: CRC mismatch"):
        list(index.fields([1]))
    index._checked.update(index._chunks)  # as if the chunk had passed
    with pytest.raises(DamagedLogError, match=match):
        list(index.fields([1]))


def test_index_past_the_end_of_the_file_is_damage() -> None:
    data = _one_chunk()
    stream = io.BytesIO(data)
    index = LogIndex.of(stream, make_reader(stream).get_summary())
    assert index is not None
    stream.truncate(data.index(b'{"n": 1}') - 10)
    with pytest.raises(CorruptChunksError, match="cut short"):
        list(index.fields([1]))


def test_indexes_missing_a_channel_are_left_to_mcap() -> None:
    data = bytearray(_recorded())
    summary = make_reader(io.BytesIO(bytes(data))).get_summary()
    assert summary is not None
    assert LogIndex.of(io.BytesIO(bytes(data)), summary) is not None
    data[summary.chunk_indexes[1].message_index_offsets[2]] = 0x7F  # no longer an index record
    assert LogIndex.of(io.BytesIO(bytes(data)), summary) is None


def test_an_error_inside_a_pass_is_not_hidden_by_close(tmp_path: Path) -> None:
    """The caller fails while a pass is open (its checking thread may still hold a chunk of the
    mapped file): closing the index neither raises nor pulls the pages from under the thread."""
    data = _recorded()
    path = tmp_path / "log.mcap"
    path.write_bytes(data)
    with path.open("rb") as f:
        index = LogIndex.of(f, make_reader(f).get_summary())
        assert index is not None
        held = index._data()[100:200]  # what a checking thread holds while it works
        with pytest.raises(KeyError, match="the caller's own error"):
            try:
                for _ in index.fields(index.channel_ids):
                    raise KeyError("the caller's own error")
            finally:
                index.close()
        assert bytes(held) == data[100:200]
        held.release()


def _range(start_ns: int | None, end_ns: int | None) -> dict[str, int | None]:
    """``[start, end)`` as mcap's ``iter_messages`` names it (``start_time`` before mcap 1.6)."""
    if "starting_at" in inspect.signature(SeekingReader.iter_messages).parameters:
        return {"starting_at": start_ns, "ending_before": end_ns}
    return {"start_time": start_ns, "end_time": end_ns}
