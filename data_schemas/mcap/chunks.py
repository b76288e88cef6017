"""A lean MCAP writer: messages are buffered as byte parts and written one chunk at a time.

mcap's own ``Writer`` copies every message about ten times (record builders, ``BytesIO``
buffers, the chunk record) before it reaches the file; for multi-megabyte frames that copying,
not the encoding, was the recorder's cost. Here a message is a short header plus the caller's
byte parts (kept, not copied), the chunk CRC is updated as parts arrive (ISA-L ``crc32``), and
:meth:`McapChunkWriter.close_chunk` joins the chunk record, its message indexes and nothing
else into one ``write``. Small records (header, metadata, schemas, channels, indexes, summary,
footer) are serialised by mcap's record classes, so the file is plain MCAP: schemas and
channels inside the chunk of their first message, message indexes after each chunk, and a
full summary (schemas, channels, statistics, chunk and metadata indexes, summary offsets).

This class knows nothing of time, locking or errors: :class:`data_schemas.mcap.writer.LogWriter`
decides when chunks close and handles failures.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import IO, Any

from isal import isal_zlib
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    McapRecord,
    MessageIndex,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

from data_schemas.mcap.layout import (
    CHUNK_FIELDS,
    FOOTER_PREFIX,
    MAGIC,
    MESSAGE_FIELDS,
    MESSAGE_HEADER,
    RECORD_HEADER,
    STORED_CHUNK_HEADER,
)

Bytes = bytes | bytearray | memoryview


def serialise(record: McapRecord) -> bytes:
    """One MCAP record (opcode, length, body) as bytes.

    Through mcap's documented record API (``McapRecord.write`` into a
    ``mcap.data_stream.RecordBuilder``, the same in mcap 1.2.2 and 1.6.0). mcap's public
    ``Writer`` cannot serve here: it writes whole files, copies each message several times, and
    cannot write a chunk with its message indexes in one ``write`` that the writer then flushes
    and ``fsync``s (what keeps an interrupted recording readable up to its last chunk). So chunk
    records are laid out by hand (:meth:`McapChunkWriter.close_chunk`), and only the small
    records go through this function.
    """
    builder = RecordBuilder()
    record.write(builder)
    data: bytes = builder.end()  # type: ignore[no-untyped-call]
    return data


@dataclass
class _OpenChunk:
    """Records of the chunk being filled, not yet written."""

    parts: list[Bytes] = field(default_factory=list)
    size: int = 0
    crc: int = 0
    messages: int = 0
    start_ns: int = 0
    end_ns: int = 0
    index: dict[int, list[tuple[int, int]]] = field(default_factory=dict)

    def add(self, parts: Sequence[Bytes]) -> int:
        """Append a record's parts; return its offset in the chunk."""
        offset = self.size
        for part in parts:
            self.parts.append(part)
            self.size += len(part)
            self.crc = isal_zlib.crc32(part, self.crc)
        return offset


def _zstd() -> Any:
    """A zstd compressor (imported only when a log asks for compressed chunks)."""
    import zstandard

    return zstandard.ZstdCompressor(level=3)


class McapChunkWriter:
    """Write an MCAP file chunk by chunk to a binary stream (see module docstring).

    Parameters
    ----------
    stream : binary stream
        Written sequentially; ``tell()`` must give the file offset.
    library : str
        The header's library string.
    compression : {"", "zstd"}
        Chunk compression: ``""`` stores chunks (frames are compressed already, and stored
        chunks can be read in place), ``"zstd"`` compresses each chunk.
    """

    def __init__(self, stream: IO[bytes], *, library: str, compression: str = "") -> None:
        if compression not in ("", "zstd"):
            raise ValueError(f"chunk compression must be '' or 'zstd', got {compression!r}")
        self._stream = stream
        self._library = library
        self._compression = compression
        self._attachment_indexes: list[AttachmentIndex] = []
        self._chunk = _OpenChunk()
        self._schemas: list[Schema] = []
        self._channels: list[Channel] = []
        self._chunk_indexes: list[ChunkIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._counts: dict[int, int] = {}
        self._messages = 0
        self._start_ns = 0
        self._end_ns = 0

    @property
    def pending_bytes(self) -> int:
        """Bytes of records in the open chunk."""
        return self._chunk.size

    @property
    def pending_messages(self) -> int:
        """Messages in the open chunk."""
        return self._chunk.messages

    def start(self, metadata: dict[str, dict[str, str]]) -> None:
        """Write the magic, the header and ``metadata`` records (name -> key/value map)."""
        self._stream.write(MAGIC + serialise(Header(profile="", library=self._library)))
        for name, values in metadata.items():
            self.add_metadata(name, values)

    def add_metadata(self, name: str, values: dict[str, str]) -> None:
        """Write a metadata record now (between chunks: the open chunk is not written yet)."""
        offset = self._stream.tell()
        data = serialise(Metadata(name=name, metadata=values))
        self._stream.write(data)
        self._metadata_indexes.append(MetadataIndex(offset, len(data), name))

    def add_attachment(self, attachment: Attachment) -> None:
        """Write an attachment record now (between chunks), indexed in the summary."""
        offset = self._stream.tell()
        data = serialise(attachment)
        self._stream.write(data)
        self._attachment_indexes.append(
            AttachmentIndex(
                offset=offset,
                length=len(data),
                log_time=attachment.log_time,
                create_time=attachment.create_time,
                data_size=len(attachment.data),
                name=attachment.name,
                media_type=attachment.media_type,
            )
        )

    def add_schema(self, name: str, encoding: str, data: bytes) -> int:
        """Register a schema (written into the open chunk); return its id."""
        schema = Schema(id=len(self._schemas) + 1, name=name, encoding=encoding, data=data)
        self._schemas.append(schema)
        self._chunk.add([serialise(schema)])
        return schema.id

    def add_channel(
        self,
        topic: str,
        message_encoding: str,
        schema_id: int,
        metadata: dict[str, str] | None = None,
    ) -> int:
        """Register a channel (written into the open chunk); return its id."""
        channel = Channel(
            id=len(self._channels) + 1,
            topic=topic,
            message_encoding=message_encoding,
            schema_id=schema_id,
            metadata=metadata or {},
        )
        self._channels.append(channel)
        self._counts[channel.id] = 0
        self._chunk.add([serialise(channel)])
        return channel.id

    def add_message(
        self,
        channel_id: int,
        sequence: int,
        log_time_ns: int,
        publish_time_ns: int,
        data: Sequence[Bytes],
    ) -> int:
        """Add a message whose data is the concatenation of ``data``; return its record size.

        The parts are kept by reference until the chunk is closed: do not modify them.
        """
        length = MESSAGE_FIELDS + sum(len(part) for part in data)
        header = MESSAGE_HEADER.pack(
            Opcode.MESSAGE, length, channel_id, sequence, log_time_ns, publish_time_ns
        )
        chunk = self._chunk
        offset = chunk.add([header, *data])
        if chunk.messages == 0:
            chunk.start_ns = chunk.end_ns = log_time_ns
        else:
            chunk.start_ns = min(chunk.start_ns, log_time_ns)
            chunk.end_ns = max(chunk.end_ns, log_time_ns)
        chunk.messages += 1
        chunk.index.setdefault(channel_id, []).append((log_time_ns, offset))
        self._counts[channel_id] += 1
        return RECORD_HEADER.size + length

    def close_chunk(self) -> bool:
        """Write the open chunk and its message indexes, flush the stream; False if empty.

        A chunk without messages stays open (its schema and channel records go with the next
        message).
        """
        chunk = self._chunk
        if chunk.messages == 0:
            return False
        if self._messages == 0:
            self._start_ns, self._end_ns = chunk.start_ns, chunk.end_ns
        else:
            self._start_ns = min(self._start_ns, chunk.start_ns)
            self._end_ns = max(self._end_ns, chunk.end_ns)
        chunk_offset = self._stream.tell()
        if self._compression:
            body = [_zstd().compress(b"".join(chunk.parts))]
            stored = len(body[0])
            name = self._compression.encode()
            head = CHUNK_FIELDS.pack(chunk.start_ns, chunk.end_ns, chunk.size, chunk.crc)
            head += struct.pack("<I", len(name)) + name + struct.pack("<Q", stored)
            head = RECORD_HEADER.pack(Opcode.CHUNK, len(head) + stored) + head
        else:
            body, stored = chunk.parts, chunk.size
            head = STORED_CHUNK_HEADER.pack(
                Opcode.CHUNK,
                STORED_CHUNK_HEADER.size - RECORD_HEADER.size + chunk.size,
                chunk.start_ns,
                chunk.end_ns,
                chunk.size,
                chunk.crc,
                0,  # compression "" (stored): frames are compressed already
                chunk.size,
            )
        chunk_length = len(head) + stored
        index_offsets: dict[int, int] = {}
        indexes: list[bytes] = []
        position = chunk_offset + chunk_length
        for channel_id, entries in chunk.index.items():
            index_offsets[channel_id] = position
            indexes.append(serialise(MessageIndex(channel_id, entries)))
            position += len(indexes[-1])
        self._stream.write(b"".join([head, *body, *indexes]))
        self._stream.flush()
        self._chunk_indexes.append(
            ChunkIndex(
                message_start_time=chunk.start_ns,
                message_end_time=chunk.end_ns,
                chunk_start_offset=chunk_offset,
                chunk_length=chunk_length,
                message_index_offsets=index_offsets,
                message_index_length=position - chunk_offset - chunk_length,
                compression=self._compression,
                compressed_size=stored,
                uncompressed_size=chunk.size,
            )
        )
        self._messages += chunk.messages
        self._chunk = _OpenChunk()
        return True

    def finish(self) -> None:
        """Close the open chunk, write the data end, summary, footer and closing magic."""
        self.close_chunk()
        self._stream.write(serialise(DataEnd(data_section_crc=0)))
        summary_start = self._stream.tell()
        groups: list[tuple[Opcode, list[bytes]]] = [
            (Opcode.SCHEMA, [serialise(s) for s in self._schemas]),
            (Opcode.CHANNEL, [serialise(c) for c in self._channels]),
            (Opcode.STATISTICS, [serialise(self._statistics())]),
            (Opcode.CHUNK_INDEX, [serialise(i) for i in self._chunk_indexes]),
            (Opcode.METADATA_INDEX, [serialise(i) for i in self._metadata_indexes]),
            (Opcode.ATTACHMENT_INDEX, [serialise(i) for i in self._attachment_indexes]),
        ]
        parts: list[bytes] = []
        offsets: list[bytes] = []
        position = summary_start
        for opcode, records in groups:
            length = sum(len(r) for r in records)
            if length:
                offsets.append(serialise(SummaryOffset(opcode, position, length)))
                parts.extend(records)
                position += length
        summary_offset_start = position
        summary = b"".join(parts + offsets)
        footer_prefix = FOOTER_PREFIX.pack(Opcode.FOOTER, 20, summary_start, summary_offset_start)
        crc = isal_zlib.crc32(footer_prefix, isal_zlib.crc32(summary))
        footer = serialise(Footer(summary_start, summary_offset_start, crc))
        self._stream.write(summary + footer + MAGIC)
        self._stream.flush()

    def _statistics(self) -> Statistics:
        return Statistics(
            attachment_count=len(self._attachment_indexes),
            channel_count=len(self._channels),
            channel_message_counts=dict(self._counts),
            chunk_count=len(self._chunk_indexes),
            message_count=self._messages,
            message_end_time=self._end_ns,
            message_start_time=self._start_ns,
            metadata_count=len(self._metadata_indexes),
            schema_count=len(self._schemas),
        )
