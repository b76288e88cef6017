"""A log still being written, read as it grows: the session first, then whole chunks in order.

The recorder's writer (``data_schemas/mcap/writer.py``) closes a chunk at least every 0.5 s and
writes it, with its message indexes, in one ``write`` followed by a flush and an ``fsync``.
Another process can therefore read the file as it grows. :class:`FollowedLog` reads each
top-level record once the file holds all of it (the record header gives its length), checks
every chunk's CRC, and yields the messages of each chunk in file order (for the recorder's logs
that is log-time order). It waits for the session metadata (the recorder writes it before the
first chunk) and checks it as :class:`data_schemas.mcap.processable.ProcessableLog` does. When
the next record is not whole yet (the end of the file, or a chunk being written) it polls the
file size. It ends by itself:

* ``end == "finished"``: the footer is written (the recorder finished the log);
* ``end == "idle"``: the file has not grown for ``idle_timeout_s`` seconds (the recorder was
  killed, stopped writing or lost its disk); :attr:`FollowedLog.end_line` says so in one line.

Nothing here writes to the log or signals the recorder: the recorder never waits for a follower.
Chunk records are split here, not by mcap's reader: mcap's public readers want a finished file
(the summary, or a stream read to its end) and cannot stop at the last whole chunk of a growing
one.
"""

from __future__ import annotations

import io
import os
import struct
import time
from collections.abc import Collection, Iterator
from pathlib import Path
from typing import Literal

from isal import isal_zlib
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Channel, Message, Metadata, Schema

from data_schemas.closing import Closing
from data_schemas.errors import (
    CorruptLogError,
    LogError,
    MissingMetadataError,
    NotMcapError,
    recover_hint,
)
from data_schemas.inputs import open_fd
from data_schemas.mcap.compression import MAX_CHUNK_BYTES, decompress
from data_schemas.mcap.layout import (
    CHUNK_FIELDS,
    MAGIC,
    MESSAGE_FIELDS,
    MESSAGE_HEADER,
    RECORD_HEADER,
)
from data_schemas.mcap.processable import check_calibration, check_channel
from data_schemas.mcap.read import IDLE_TIMEOUT_S, LogMessage
from data_schemas.registry import SESSION_METADATA_NAME
from data_schemas.session import Session, session_from_metadata
from data_schemas.shape import brief

_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")

FollowEnd = Literal["finished", "idle"]
#: The largest chunk or metadata record read whole (bytes): a chunk's limit and its header.
MAX_RECORD_BYTES = MAX_CHUNK_BYTES + 4096
#: A record of a chunk: a schema, a channel, or a message.
_ChunkRecord = Schema | Channel | Message


class FollowedLog(Closing):
    """A log followed while it grows (see the module docstring).

    Parameters
    ----------
    path : str or os.PathLike
        The ``.mcap`` file. It may not exist yet: it is waited for up to ``idle_timeout_s``.
    idle_timeout_s : float
        Stop once the file has not grown for this long (seconds, > 0).
    poll_s : float
        Period of the file-size checks while waiting (seconds).

    Attributes
    ----------
    metadata : dict
        Metadata records before the first chunk (name -> key/value map).
    session : Session
        The log's session.
    notes : list of str
        Foreign channels ignored, one line each.
    end : {"finished", "idle"} or None
        Why reading stopped: the footer is written, or the time-out; None while reading.
    chunk_count : int
        Whole chunks read so far.

    Raises
    ------
    LogError
        The file did not appear in time, ended before any chunk, shrank while followed, or a
        whole chunk fails its CRC (the last when its messages are read).
    NotMcapError, MissingMetadataError, SchemaError
        The file is not MCAP, or its session is missing or invalid.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        idle_timeout_s: float = IDLE_TIMEOUT_S,
        poll_s: float = 0.05,
    ) -> None:
        if not idle_timeout_s > 0:
            raise ValueError(f"idle timeout must be > 0 s, got {idle_timeout_s}")
        self.path = Path(path)
        self.name = self.path.name
        self.idle_timeout_s = float(idle_timeout_s)
        self.notes: list[str] = []
        self.end: FollowEnd | None = None
        self.chunk_count = 0
        self._shown = os.fspath(path)  # the path as given, in messages
        self._poll_s = poll_s
        self._fd: int | None = None
        self._pos = 0
        self._size = -1
        self._grew_at = 0.0
        self._held: tuple[int, bytes] | None = None
        self._schemas: dict[int, str] = {}
        self._channels: dict[int, tuple[str, str]] = {}
        try:
            self.metadata = self._read_metadata()
            check_calibration(self.name, self.metadata)
            try:
                self.session: Session = session_from_metadata(self.metadata[SESSION_METADATA_NAME])
            except MissingMetadataError as exc:
                raise MissingMetadataError(f"{self.name}: {exc}") from None
        except BaseException:
            self.close()
            raise

    # ------------------------------------------------------------------ public API
    def messages(self, topics: Collection[str] | None = None) -> Iterator[LogMessage]:
        """Messages of ``topics`` (all if None) as whole chunks arrive, until the log ends.

        Raises
        ------
        UnknownSchemaError
            One of our channels has a schema this version cannot read (checked when it first
            appears); another tool's channel is ignored with a line in :attr:`notes`.
        LogError
            A whole chunk is damaged (the chunks before it were read).
        """
        usable: dict[tuple[str, str], bool] = {}
        for topic, schema, message in self._messages():
            if (topic, schema) not in usable:
                note = check_channel(self.name, topic, schema)
                if note is not None:
                    self.notes.append(note)
                usable[(topic, schema)] = note is None
            if usable[(topic, schema)] and (topics is None or topic in topics):
                yield LogMessage(
                    topic,
                    schema,
                    message.log_time,
                    message.publish_time,
                    message.sequence,
                    message.data,
                )

    @property
    def end_line(self) -> str:
        """One line: why following stopped (empty while it goes on)."""
        if self.end == "finished":
            return f"{self._shown} is finished (footer written)"
        if self.end == "idle":
            return (
                f"{self._shown} has not grown for {self.idle_timeout_s:g} s: stopped following "
                f"after {self.chunk_count} chunk{'' if self.chunk_count == 1 else 's'} (was the "
                "recorder stopped or killed? "
                "`bslam recover` indexes an unfinished log)"
            )
        return ""

    def close(self) -> None:
        """Close the file."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    # ------------------------------------------------------------------ internals
    def _read_metadata(self) -> dict[str, dict[str, str]]:
        """Metadata records before the first chunk; waits for the file and that chunk."""
        found: dict[str, dict[str, str]] = {}
        while True:
            record = self._next_record()
            if record is None or record[0] == Opcode.CHUNK:
                break
            if record[0] == Opcode.METADATA:
                meta = Metadata.read(ReadDataStream(io.BytesIO(record[1])))
                found[meta.name] = dict(meta.metadata)
        if record is None and not found:
            raise LogError(f"{self._shown}: {self.end_line}; it holds no session yet")
        self._held = record
        return found

    def _messages(self) -> Iterator[tuple[str, str, Message]]:
        """(topic, schema name, message) of every whole chunk, in file order, until the end."""
        while True:
            record = self._held if self._held is not None else self._next_record()
            self._held = None
            if record is None:
                return
            opcode, body = record
            if opcode == Opcode.CHUNK:
                yield from self._chunk_messages(body)

    def _open(self) -> int:
        if self._fd is not None:
            return self._fd
        deadline = time.monotonic() + self.idle_timeout_s
        while True:
            try:
                # a FIFO opens at once (no wait for a writer); it never grows, so the idle
                # time-out ends the follow
                self._fd = open_fd(self._shown, what="log", error=LogError, fifo=True)
                break
            except FileNotFoundError:
                if time.monotonic() >= deadline:
                    raise LogError(
                        f"{self._shown} did not appear within {self.idle_timeout_s:g} s; is the "
                        "recorder writing to this path?"
                    ) from None
                time.sleep(self._poll_s)
            except OSError as exc:
                raise LogError(f"cannot open log {self._shown}: {exc.strerror}") from None
        self._grew_at = time.monotonic()
        return self._fd

    def _wait_for(self, end: int) -> bool:
        """Wait until the file holds ``end`` bytes; False (and ``end = "idle"``) on time-out."""
        fd = self._open()
        while True:
            size = os.fstat(fd).st_size
            if size < self._pos:
                raise LogError(
                    f"{self._shown} shrank below byte {self._pos} while followed (rewritten?)"
                )
            if size != self._size:
                self._size, self._grew_at = size, time.monotonic()
            if size >= end:
                return True
            if time.monotonic() - self._grew_at >= self.idle_timeout_s:
                self.end = "idle"
                return False
            time.sleep(self._poll_s)

    def _read(self, start: int, length: int) -> bytes:
        assert self._fd is not None
        return os.pread(self._fd, length, start)

    def _next_record(self) -> tuple[int, bytes] | None:
        """The next whole top-level record (opcode, body); None once the log ended."""
        if self.end is not None:
            return None
        if self._pos == 0:
            if not self._wait_for(len(MAGIC)):
                return None
            if self._read(0, len(MAGIC)) != MAGIC:
                raise NotMcapError(f"{self._shown} is not an MCAP file (bad magic bytes)")
            self._pos = len(MAGIC)
        while True:
            if not self._wait_for(self._pos + RECORD_HEADER.size):
                return None
            opcode, length = RECORD_HEADER.unpack(self._read(self._pos, RECORD_HEADER.size))
            start = self._pos + RECORD_HEADER.size
            if opcode == Opcode.FOOTER:
                self.end = "finished"
                return None
            if opcode in (Opcode.CHUNK, Opcode.METADATA) and length > MAX_RECORD_BYTES:
                raise CorruptLogError(
                    f"{self._shown}: a record at byte {self._pos} states {brief(length)} bytes, "
                    f"over the limit of {MAX_RECORD_BYTES}; {recover_hint(self._shown)}"
                )
            if not self._wait_for(start + length):
                return None
            self._pos = start + length
            if opcode in (Opcode.CHUNK, Opcode.METADATA):
                return opcode, self._read(start, length)
            # header, message indexes, data end and the summary: nothing to yield

    def _chunk_messages(self, body: bytes) -> Iterator[tuple[str, str, Message]]:
        at = self._pos - len(body) - RECORD_HEADER.size
        try:
            records = _chunk_records(body)
        except (McapError, struct.error, ValueError) as exc:
            raise LogError(
                f"{self._shown}: the chunk at byte {at} is damaged ({exc}); the chunks before "
                "it were read"
            ) from None
        self.chunk_count += 1
        for record in records:
            if isinstance(record, Schema):
                self._schemas[record.id] = record.name
            elif isinstance(record, Channel):
                schema = self._schemas.get(record.schema_id, "")
                self._channels[record.id] = (record.topic, schema)
            else:
                topic, schema = self._channels.get(record.channel_id, ("", ""))
                if not topic:
                    raise LogError(
                        f"{self._shown}: a message in the chunk at byte {at} has no channel record"
                    )
                yield topic, schema, record


def _chunk_records(body: bytes) -> list[_ChunkRecord]:
    """The records of a chunk record's ``body``, its CRC checked.

    A compressed chunk is decompressed within its limits (:func:`decompress`). The recorder's
    chunks are stored (frames are PNG already): they are split in place, CRC with ISA-L and each
    message's data sliced out once, a third of the cost of mcap's record-by-record reader.

    Raises
    ------
    ValueError
        Unknown compression, data that does not decompress, a CRC or a record length that does
        not match.
    """
    _, _, size, crc = CHUNK_FIELDS.unpack_from(body)
    (name_length,) = _U32.unpack_from(body, CHUNK_FIELDS.size)
    at = CHUNK_FIELDS.size + _U32.size + name_length
    compression = bytes(body[CHUNK_FIELDS.size + _U32.size : at]).decode()
    (length,) = _U64.unpack_from(body, at)
    start = at + _U64.size
    view = memoryview(body)[start : start + length]
    if len(view) != length:
        raise ValueError(f"records of {len(view)} bytes where the chunk says {length}")
    if compression:
        view = memoryview(decompress(compression, view, size))
    elif length != size:
        raise ValueError(f"records of {length} bytes where the chunk says {size}")
    if crc and isal_zlib.crc32(view) != crc:
        raise ValueError("CRC mismatch")
    out: list[_ChunkRecord] = []
    pos = 0
    while pos < len(view):
        opcode, n = RECORD_HEADER.unpack_from(view, pos)
        end = pos + RECORD_HEADER.size + n
        if end > len(view) or (opcode == Opcode.MESSAGE and n < MESSAGE_FIELDS):
            raise ValueError("a record is cut short")
        if opcode == Opcode.MESSAGE:
            _, _, channel_id, sequence, log_time, publish_time = MESSAGE_HEADER.unpack_from(
                view, pos
            )
            data = bytes(view[pos + MESSAGE_HEADER.size : end])
            out.append(Message(channel_id, log_time, data, publish_time, sequence))
        elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL):
            kind = Schema if opcode == Opcode.SCHEMA else Channel
            out.append(kind.read(ReadDataStream(io.BytesIO(view[pos + RECORD_HEADER.size : end]))))
        pos = end
    return out
