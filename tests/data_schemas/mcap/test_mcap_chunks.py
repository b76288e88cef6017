"""McapChunkWriter writes plain MCAP: checked with mcap's own readers and against the spec."""

from __future__ import annotations

import io
import struct
import zlib

from mcap.data_stream import ReadDataStream
from mcap.reader import make_reader
from mcap.records import Chunk, DataEnd, Footer, Header, MessageIndex, Metadata
from mcap.stream_reader import StreamReader

from data_schemas.mcap.chunks import McapChunkWriter
from data_schemas.mcap.layout import MAGIC
from tests.mcap_library import chunk_records


def _write(chunks: list[list[tuple[int, int, list[bytes]]]]) -> bytes:
    """A file with two channels; each chunk is a list of (channel, log_time, data parts)."""
    out = io.BytesIO()
    mcap = McapChunkWriter(out, library="test")
    mcap.start({"meta": {"k": "v"}})
    schema = mcap.add_schema("s", "jsonschema", b"{}")
    channels = {1: mcap.add_channel("/a", "json", schema), 2: mcap.add_channel("/b", "json", 0)}
    seq = 0
    for chunk in chunks:
        for channel, t_ns, parts in chunk:
            seq += 1
            mcap.add_message(channels[channel], seq, t_ns, t_ns + 1, parts)
        assert mcap.close_chunk()
    mcap.finish()
    return out.getvalue()


CHUNKS = [
    [(1, 100, [b'{"x":', b"1}"]), (2, 90, [b"{}"]), (1, 120, [b'{"x":2}'])],
    [(2, 200, [b"{", b'"y"', b":3}"])],
]


def test_messages_round_trip_through_mcap_readers() -> None:
    data = _write(CHUNKS)
    reader = make_reader(io.BytesIO(data), validate_crcs=True)
    got = [(c.topic, m.log_time, m.publish_time, m.data) for _, c, m in reader.iter_messages()]
    assert sorted(got, key=lambda g: g[1]) == [
        ("/b", 90, 91, b"{}"),
        ("/a", 100, 101, b'{"x":1}'),
        ("/a", 120, 121, b'{"x":2}'),
        ("/b", 200, 201, b'{"y":3}'),
    ]
    records = list(StreamReader(io.BytesIO(data), validate_crcs=True, emit_chunks=True).records)
    assert isinstance(records[0], Header) and records[0].library == "test"
    assert isinstance(records[1], Metadata) and records[1].metadata == {"k": "v"}
    assert isinstance(records[-1], Footer)
    assert sum(isinstance(r, DataEnd) for r in records) == 1


def test_summary_statistics_and_chunk_indexes() -> None:
    data = _write(CHUNKS)
    summary = make_reader(io.BytesIO(data)).get_summary()
    assert summary is not None and summary.statistics is not None
    stats = summary.statistics
    assert (stats.message_count, stats.chunk_count, stats.channel_count) == (4, 2, 2)
    assert (stats.schema_count, stats.metadata_count) == (1, 1)
    assert (stats.message_start_time, stats.message_end_time) == (90, 200)
    assert dict(stats.channel_message_counts) == {1: 2, 2: 2}
    assert [(i.message_start_time, i.message_end_time) for i in summary.chunk_indexes] == [
        (90, 120),
        (200, 200),
    ]
    assert [s.name for s in summary.schemas.values()] == ["s"]
    assert [c.topic for c in summary.channels.values()] == ["/a", "/b"]
    for index in summary.chunk_indexes:  # each chunk index points at its whole chunk record
        opcode, length = struct.unpack_from("<BQ", data, index.chunk_start_offset)
        assert (opcode, index.chunk_length) == (0x06, 9 + length)
        assert index.uncompressed_size == index.compressed_size > 0


def test_message_indexes_point_at_their_messages() -> None:
    data = _write(CHUNKS)
    summary = make_reader(io.BytesIO(data)).get_summary()
    assert summary is not None
    checked = 0
    for index in summary.chunk_indexes:
        body = data[index.chunk_start_offset + 9 : index.chunk_start_offset + index.chunk_length]
        chunk_records = Chunk.read(_stream(body))
        for channel_id, offset in index.message_index_offsets.items():
            (opcode,) = struct.unpack_from("<B", data, offset)
            assert opcode == 0x07  # message index
            (length,) = struct.unpack_from("<Q", data, offset + 1)
            record = MessageIndex.read(_stream(data[offset + 9 : offset + 9 + length]))
            assert record.channel_id == channel_id
            for log_time, at in record.records:
                # message record at `at` inside the chunk's records: opcode, length, channel,
                # sequence, log_time
                op, _, channel, _, t_ns = struct.unpack_from("<BQHIQ", chunk_records.data, at)
                assert (op, channel, t_ns) == (0x05, channel_id, log_time)
                checked += 1
    assert checked == 4


def test_summary_crc_matches_the_spec() -> None:
    data = _write(CHUNKS)
    assert data.endswith(MAGIC)
    footer_at = len(data) - len(MAGIC) - (1 + 8 + 20)
    opcode, length, summary_start, offset_start, crc = struct.unpack_from("<BQQQI", data, footer_at)
    assert (opcode, length) == (0x02, 20)
    assert summary_start < offset_start < footer_at
    # CRC of the summary section and the footer up to (not including) the CRC field
    assert crc == zlib.crc32(data[summary_start : footer_at + 1 + 8 + 16])


def test_chunk_crc_covers_every_part() -> None:
    data = _write(CHUNKS)
    chunks = [
        r for r in StreamReader(io.BytesIO(data), emit_chunks=True).records if isinstance(r, Chunk)
    ]
    assert len(chunks) == 2
    for chunk in chunks:
        assert chunk.compression == ""
        assert chunk.uncompressed_crc == zlib.crc32(chunk.data) != 0
        assert chunk_records(chunk)


def test_a_chunk_without_messages_stays_open() -> None:
    out = io.BytesIO()
    mcap = McapChunkWriter(out, library="test")
    mcap.start({})
    channel = mcap.add_channel("/a", "json", mcap.add_schema("s", "jsonschema", b"{}"))
    size = len(out.getvalue())
    assert not mcap.close_chunk()
    assert len(out.getvalue()) == size and mcap.pending_bytes > 0
    mcap.add_message(channel, 1, 5, 5, [b"{}"])
    assert mcap.pending_messages == 1
    mcap.finish()
    reader = make_reader(io.BytesIO(out.getvalue()), validate_crcs=True)
    assert [(c.topic, m.data) for _, c, m in reader.iter_messages()] == [("/a", b"{}")]


def _stream(body: bytes) -> ReadDataStream:
    return ReadDataStream(io.BytesIO(body))
