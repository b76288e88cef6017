"""Read bearing-slam logs, finished or not; summarise them; recover unfinished ones.

An unfinished log (the recorder was killed, or the disk filled up) has no summary or footer,
so mcap's ``make_reader`` cannot index it. :class:`LogReader` reads records in file order and
stops cleanly at the first incomplete or corrupt record (chunk CRCs are checked), so every
complete chunk is readable. :func:`recover_log` rewrites those into a new, indexed file.
"""

from __future__ import annotations

import io
import os
import struct
import zlib
from collections.abc import Collection, Iterator
from dataclasses import dataclass, field
from types import TracebackType
from typing import IO, Any

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Message, Metadata, Schema
from mcap.stream_reader import CRCValidationError, breakup_chunk

from data_schemas.codec import decode
from data_schemas.errors import (
    LogError,
    MissingMetadataError,
    NotMcapError,
    UnfinishedLogError,
)
from data_schemas.registry import SESSION_METADATA_NAME
from data_schemas.session import Session, session_from_metadata
from data_schemas.shape import check_shape
from recorder.mcapout import MAGIC, RECORD_HEADER, McapChunkWriter

Source = str | os.PathLike[str] | IO[bytes]
#: Chunk size of a recovered log.
_RECOVER_CHUNK_BYTES = 4 * 1024 * 1024


@dataclass(frozen=True)
class LogMessage:
    """One message of a log, not yet decoded.

    Attributes
    ----------
    topic, schema : str
        Channel topic and schema name.
    log_time_ns, publish_time_ns : int
        When the recorder wrote it, and the message's own ``timestamp`` (ns since the epoch).
    sequence : int
        Per-channel counter from 1.
    data : bytes
        The JSON message.
    """

    topic: str
    schema: str
    log_time_ns: int
    publish_time_ns: int
    sequence: int
    data: bytes = field(repr=False)

    def decode(self) -> dict[str, Any]:
        """The message as a dict: JSON decoded, required fields and their types checked.

        Raises
        ------
        SchemaError
            One line naming the topic, the log time and the field.
        """
        msg = decode(self.topic, self.data)
        check_shape(self.schema, msg, topic=self.topic, log_time_ns=self.log_time_ns)
        return msg


class LogReader:
    """Stream a bearing-slam MCAP log in file order.

    Parameters
    ----------
    source : str, os.PathLike or binary stream (seekable)
        The log. A path is opened and closed by the reader.
    allow_unfinished : bool
        Read an unfinished log (up to its last complete chunk) instead of raising
        :class:`UnfinishedLogError`.

    Raises
    ------
    NotMcapError
        The file does not start with the MCAP magic.
    UnfinishedLogError
        The log has no footer and ``allow_unfinished`` is false (says how many messages are
        readable and suggests ``bslam recover``).
    """

    def __init__(self, source: Source, *, allow_unfinished: bool = False) -> None:
        if isinstance(source, str | os.PathLike):
            self.name = os.fspath(source)
            try:
                self._stream: IO[bytes] = open(self.name, "rb")  # noqa: SIM115 (closed in close)
            except OSError as exc:
                raise LogError(f"cannot open log {self.name}: {exc.strerror}") from None
            self._owned = True
        else:
            self._stream = source
            self.name = str(getattr(source, "name", "<stream>"))
            self._owned = False
        try:
            self._start = self._stream.tell()
            self._size = self._stream.seek(0, io.SEEK_END) - self._start
            self._stream.seek(self._start)
            if self._stream.read(len(MAGIC)) != MAGIC:
                raise NotMcapError(f"{self.name} is not an MCAP file (bad magic bytes)")
            self.finished = self._has_footer()
            self.metadata = self._leading_metadata()
            if not self.finished and not allow_unfinished:
                count = sum(1 for _ in self.messages())
                raise UnfinishedLogError(
                    f"{self.name} is unfinished (the recording was interrupted): {count} "
                    f"messages are readable; run `bslam recover {self.name} FIXED.mcap`"
                )
        except BaseException:
            self.close()
            raise
        #: bytes after the last complete record of the last :meth:`messages` pass
        self.trailing_bytes = 0
        #: complete chunks seen in the last :meth:`messages` pass
        self.chunk_count = 0

    # ------------------------------------------------------------------ public API
    def session(self) -> Session:
        """The typed session document (raise MissingMetadataError / SchemaError)."""
        record = self.metadata.get(SESSION_METADATA_NAME)
        if record is None:
            raise MissingMetadataError(
                f"{self.name} has no {SESSION_METADATA_NAME!r} metadata record "
                "(not a bearing-slam recording?)"
            )
        return session_from_metadata(record)

    def messages(self, topics: Collection[str] | None = None) -> Iterator[LogMessage]:
        """Messages in file order (write order), optionally only some topics."""
        schemas: dict[int, str] = {}
        channels: dict[int, tuple[str, str]] = {}
        for record in self.raw_records():
            if isinstance(record, Schema):
                schemas[record.id] = record.name
            elif isinstance(record, Channel):
                channels[record.id] = (record.topic, schemas.get(record.schema_id, ""))
            else:
                topic_name, schema_name = channels[record.channel_id]
                if topics is None or topic_name in topics:
                    yield LogMessage(
                        topic_name,
                        schema_name,
                        record.log_time,
                        record.publish_time,
                        record.sequence,
                        record.data,
                    )

    def raw_records(self) -> Iterator[Schema | Channel | Message]:
        """Schema, channel and message records of every complete chunk, in file order."""
        self.chunk_count = 0
        for record in self._records():
            if isinstance(record, Chunk):
                self.chunk_count += 1
                for inner in breakup_chunk(record):
                    if isinstance(inner, Schema | Channel | Message):
                        yield inner

    def close(self) -> None:
        """Close the file if the reader opened it."""
        if self._owned:
            self._stream.close()

    def __enter__(self) -> LogReader:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # ------------------------------------------------------------------ internals
    def _has_footer(self) -> bool:
        tail = 1 + 8 + 20 + len(MAGIC)  # footer record + closing magic
        if self._size < len(MAGIC) + tail:
            return False
        self._stream.seek(self._start + self._size - tail)
        data = self._stream.read(tail)
        return data[-len(MAGIC) :] == MAGIC and data[0] == Opcode.FOOTER

    def _leading_metadata(self) -> dict[str, dict[str, str]]:
        """Metadata records before the first chunk (the recorder writes the session first)."""
        found: dict[str, dict[str, str]] = {}
        for record in self._records(stop_at_chunk=True):
            if isinstance(record, Metadata):
                found[record.name] = dict(record.metadata)
        return found

    def _records(self, *, stop_at_chunk: bool = False) -> Iterator[Metadata | Chunk]:
        """Complete top-level metadata and chunk records; stop at the footer or the damage.

        With ``stop_at_chunk``, stop before the first chunk instead (not read, not checked).
        """
        end = self._start + self._size
        pos = self._start + len(MAGIC)
        self.trailing_bytes = 0
        while True:
            self._stream.seek(pos)
            header = self._stream.read(RECORD_HEADER.size)
            if len(header) < RECORD_HEADER.size:
                self.trailing_bytes = end - pos
                return
            opcode, length = RECORD_HEADER.unpack(header)
            body_start = pos + RECORD_HEADER.size
            if length > end - body_start:
                self.trailing_bytes = end - pos
                return
            if opcode == Opcode.FOOTER or (stop_at_chunk and opcode == Opcode.CHUNK):
                return
            if opcode in (Opcode.METADATA, Opcode.CHUNK):
                body = self._stream.read(length)
                record = _parse(opcode, body)
                if record is None:
                    self.trailing_bytes = end - pos
                    return
                yield record
            pos = body_start + length


def _parse(opcode: int, body: bytes) -> Metadata | Chunk | None:
    """A metadata or (CRC-checked) chunk record, or None if it is corrupt."""
    stream = ReadDataStream(io.BytesIO(body))
    try:
        if opcode == Opcode.METADATA:
            metadata: Metadata = Metadata.read(stream)
            return metadata
        chunk: Chunk = Chunk.read(stream)
        breakup_chunk(chunk, validate_crc=True)  # decompress + CRC: is the chunk whole?
        return chunk
    except (McapError, CRCValidationError, struct.error, UnicodeDecodeError, zlib.error):
        return None
    except Exception as exc:  # zstd/lz4 raise their own error types on damaged data
        if type(exc).__module__.split(".")[0] in ("zstandard", "lz4", "_lz4"):
            return None
        raise


# ---------------------------------------------------------------------- summary for `info`
@dataclass(frozen=True)
class ChannelSummary:
    """One channel of a log: topic, schema name and message count."""

    topic: str
    schema: str
    count: int


@dataclass(frozen=True)
class LogSummary:
    """What ``bslam info`` prints about a log.

    Attributes
    ----------
    finished : bool
        True if the log has a summary and footer (indexed); False if it was interrupted.
    channels : list of ChannelSummary
        In order of first appearance.
    message_count : int
        Readable messages (for an unfinished log: those in complete chunks).
    start_ns, end_ns : int or None
        First and last ``log_time`` (ns since the epoch), None for an empty log.
    metadata : dict
        Metadata records: name -> key/value map.
    trailing_bytes : int
        Bytes after the last complete record (an interrupted chunk), 0 if none.
    """

    name: str
    finished: bool
    channels: list[ChannelSummary]
    message_count: int
    chunk_count: int
    start_ns: int | None
    end_ns: int | None
    metadata: dict[str, dict[str, str]]
    trailing_bytes: int

    @property
    def duration_s(self) -> float:
        """Time between the first and last message, seconds (0 for an empty log)."""
        if self.start_ns is None or self.end_ns is None:
            return 0.0
        return (self.end_ns - self.start_ns) / 1e9


def log_summary(source: Source) -> LogSummary:
    """Summarise a log, finished or not (one streaming pass)."""
    with LogReader(source, allow_unfinished=True) as reader:
        counts: dict[str, int] = {}
        schemas: dict[str, str] = {}
        start: int | None = None
        end: int | None = None
        n = 0
        for msg in reader.messages():
            counts[msg.topic] = counts.get(msg.topic, 0) + 1
            schemas.setdefault(msg.topic, msg.schema)
            start = msg.log_time_ns if start is None else min(start, msg.log_time_ns)
            end = msg.log_time_ns if end is None else max(end, msg.log_time_ns)
            n += 1
        return LogSummary(
            name=reader.name,
            finished=reader.finished,
            channels=[ChannelSummary(t, schemas[t], c) for t, c in counts.items()],
            message_count=n,
            chunk_count=reader.chunk_count,
            start_ns=start,
            end_ns=end,
            metadata=reader.metadata,
            trailing_bytes=reader.trailing_bytes,
        )


# ---------------------------------------------------------------------- recover
@dataclass(frozen=True)
class RecoverReport:
    """What :func:`recover_log` kept: messages, chunks read, channels, bytes dropped."""

    messages: int
    chunks: int
    channels: int
    dropped_bytes: int
    was_finished: bool


def recover_log(broken: str | os.PathLike[str], fixed: str | os.PathLike[str]) -> RecoverReport:
    """Rewrite every complete chunk of ``broken`` into a new indexed log ``fixed``.

    Metadata records, schemas, channels and message times are kept as they were.

    Raises
    ------
    LogError
        ``fixed`` is ``broken``, or it cannot be written.
    NotMcapError
        ``broken`` is not an MCAP file.
    """
    if os.path.abspath(broken) == os.path.abspath(fixed):
        raise LogError(f"recover writes a new file: give an output path other than {broken}")
    with LogReader(broken, allow_unfinished=True) as reader:
        try:
            out = open(fixed, "wb")  # noqa: SIM115 (closed below)
        except OSError as exc:
            raise LogError(f"cannot create {os.fspath(fixed)}: {exc.strerror}") from None
        with out:
            writer = McapChunkWriter(out, library="bearing-slam recover")
            writer.start(reader.metadata)
            schema_ids: dict[int, int] = {}
            channel_ids: dict[int, int] = {}
            messages = 0
            for record in reader.raw_records():
                if isinstance(record, Schema):
                    if record.id not in schema_ids:
                        schema_ids[record.id] = writer.add_schema(
                            record.name, record.encoding, record.data
                        )
                elif isinstance(record, Channel):
                    if record.id not in channel_ids:
                        channel_ids[record.id] = writer.add_channel(
                            record.topic,
                            record.message_encoding,
                            schema_ids.get(record.schema_id, 0),
                            dict(record.metadata),
                        )
                else:
                    writer.add_message(
                        channel_ids[record.channel_id],
                        record.sequence,
                        record.log_time,
                        record.publish_time,
                        [record.data],
                    )
                    messages += 1
                    if writer.pending_bytes >= _RECOVER_CHUNK_BYTES:
                        writer.close_chunk()
            writer.finish()
        return RecoverReport(
            messages=messages,
            chunks=reader.chunk_count,
            channels=len(channel_ids),
            dropped_bytes=reader.trailing_bytes,
            was_finished=reader.finished,
        )
