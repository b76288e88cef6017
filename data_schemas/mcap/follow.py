"""Follow an MCAP log while it is being written: whole chunks only, in file order.

The recorder's writer (``data_schemas/mcap/writer.py``) closes a chunk at least every 0.5 s and
writes it, with its message indexes, in one ``write`` followed by a flush and an ``fsync``.
Another process can therefore read the file as it grows. :class:`LogFollower` reads each
top-level record once the file holds all of it (the record header gives its length), checks
every chunk's CRC, and yields the messages of each chunk in file order (for the recorder's logs
that is log-time order). When the next record is not whole yet (the end of the file, or a chunk
being written) it polls the file size. It ends by itself:

* ``end == "finished"``: the footer is written (the recorder finished the log);
* ``end == "idle"``: the file has not grown for ``idle_timeout_s`` seconds (the recorder was
  killed, stopped writing or lost its disk); :attr:`LogFollower.end_line` says so in one line.

Nothing here writes to the log or signals the recorder: the recorder never waits for a follower.
"""

from __future__ import annotations

import io
import os
import struct
import time
import zlib
from collections.abc import Callable, Iterator
from dataclasses import replace
from typing import Literal, NamedTuple

from isal import isal_zlib
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, McapRecord, Message, Metadata, Schema
from mcap.stream_reader import CRCValidationError, breakup_chunk

from data_schemas.closing import Closing
from data_schemas.errors import CorruptLogError, LogError, NotMcapError, recover_hint
from data_schemas.inputs import open_fd
from data_schemas.mcap.compression import MAX_CHUNK_BYTES, decompress
from data_schemas.mcap.layout import MAGIC, RECORD_HEADER
from data_schemas.shape import brief

#: Chunk body up to its compression name: start and end time, records size, CRC, name length;
#: the records' length (u64) follows the name.
_CHUNK_HEAD = struct.Struct("<QQQII")
_U64 = struct.Struct("<Q")
#: Message body up to its data: channel id, sequence, log time, publish time.
_MESSAGE_HEAD = struct.Struct("<HIQQ")

FollowEnd = Literal["finished", "idle"]
#: Default seconds without growth before following stops (the recorder closes a chunk at least
#: every 0.5 s while it writes, and it writes while the robot moves or is polled).
IDLE_TIMEOUT_S = 10.0
#: The largest chunk or metadata record read whole (bytes): a chunk's limit and its header.
MAX_RECORD_BYTES = MAX_CHUNK_BYTES + 4096


class FollowedMessage(NamedTuple):
    """One message of the followed log: channel topic, schema name, and the MCAP record."""

    topic: str
    schema: str
    message: Message


class LogFollower(Closing):
    """Read a growing MCAP log (see the module docstring).

    Parameters
    ----------
    path : str or os.PathLike
        The log. It may not exist yet: the follower waits ``appear_timeout_s`` for it.
    idle_timeout_s : float
        Stop once the file has not grown for this long (seconds, > 0).
    appear_timeout_s : float, optional
        How long to wait for the file to appear (default ``idle_timeout_s``).
    poll_s : float
        Period of the size checks while waiting (seconds).
    monotonic, sleep : callable
        Time source and sleep (seconds); injectable for tests.

    Raises
    ------
    LogError
        The file did not appear in time, shrank while followed, or a whole chunk fails its CRC.
    NotMcapError
        The file does not start with the MCAP magic.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        idle_timeout_s: float = IDLE_TIMEOUT_S,
        appear_timeout_s: float | None = None,
        poll_s: float = 0.05,
        monotonic: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        if not idle_timeout_s > 0:
            raise ValueError(f"idle timeout must be > 0 s, got {idle_timeout_s}")
        self.name = os.fspath(path)
        self.idle_timeout_s = float(idle_timeout_s)
        self._appear_s = self.idle_timeout_s if appear_timeout_s is None else appear_timeout_s
        self._poll_s = poll_s
        self._now = monotonic
        self._sleep = sleep
        self._fd: int | None = None
        self._pos = 0
        self._size = -1
        self._grew_at = 0.0
        self._held: tuple[int, bytes] | None = None
        self._schemas: dict[int, str] = {}
        self._channels: dict[int, tuple[str, str]] = {}
        self._metadata: dict[str, dict[str, str]] | None = None
        #: why reading stopped (None while following)
        self.end: FollowEnd | None = None
        #: whole chunks read so far
        self.chunk_count = 0

    # ------------------------------------------------------------------ public API
    @property
    def metadata(self) -> dict[str, dict[str, str]]:
        """Metadata records before the first chunk (name -> key/value map).

        Waits for the file and for its first chunk (the recorder writes the session first).

        Raises
        ------
        LogError
            The log ended (idle or finished) before any chunk.
        """
        if self._metadata is None:
            found: dict[str, dict[str, str]] = {}
            while True:
                record = self._next_record()
                if record is None or record[0] == Opcode.CHUNK:
                    break
                if record[0] == Opcode.METADATA:
                    meta = Metadata.read(ReadDataStream(io.BytesIO(record[1])))
                    found[meta.name] = dict(meta.metadata)
            if record is None and not found:
                raise LogError(f"{self.name}: {self.end_line}; it holds no session yet")
            self._held = record
            self._metadata = found
        return self._metadata

    def messages(self) -> Iterator[FollowedMessage]:
        """Messages of every whole chunk, in file order, until the log ends (see :attr:`end`)."""
        _ = self.metadata
        while True:
            record = self._held if self._held is not None else self._next_record()
            self._held = None
            if record is None:
                return
            opcode, body = record
            if opcode == Opcode.CHUNK:
                yield from self._chunk_messages(body)

    @property
    def end_line(self) -> str:
        """One line: why following stopped (empty while it goes on)."""
        if self.end == "finished":
            return f"{self.name} is finished (footer written)"
        if self.end == "idle":
            return (
                f"{self.name} has not grown for {self.idle_timeout_s:g} s: stopped following "
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
    def _open(self) -> int:
        if self._fd is not None:
            return self._fd
        deadline = self._now() + self._appear_s
        while True:
            try:
                # a FIFO opens at once (no wait for a writer); it never grows, so the idle
                # time-out ends the follow
                self._fd = open_fd(self.name, what="log", error=LogError, fifo=True)
                break
            except FileNotFoundError:
                if self._now() >= deadline:
                    raise LogError(
                        f"{self.name} did not appear within {self._appear_s:g} s; is the "
                        "recorder writing to this path?"
                    ) from None
                self._sleep(self._poll_s)
            except OSError as exc:
                raise LogError(f"cannot open log {self.name}: {exc.strerror}") from None
        self._grew_at = self._now()
        return self._fd

    def _wait_for(self, end: int) -> bool:
        """Wait until the file holds ``end`` bytes; False (and ``end = "idle"``) on time-out."""
        fd = self._open()
        while True:
            size = os.fstat(fd).st_size
            if size < self._pos:
                raise LogError(
                    f"{self.name} shrank below byte {self._pos} while followed (rewritten?)"
                )
            if size != self._size:
                self._size, self._grew_at = size, self._now()
            if size >= end:
                return True
            if self._now() - self._grew_at >= self.idle_timeout_s:
                self.end = "idle"
                return False
            self._sleep(self._poll_s)

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
                raise NotMcapError(f"{self.name} is not an MCAP file (bad magic bytes)")
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
                    f"{self.name}: a record at byte {self._pos} states {brief(length)} bytes, "
                    f"over the limit of {MAX_RECORD_BYTES}; {recover_hint(self.name)}"
                )
            if not self._wait_for(start + length):
                return None
            self._pos = start + length
            if opcode in (Opcode.CHUNK, Opcode.METADATA):
                return opcode, self._read(start, length)
            # header, message indexes, data end and the summary: nothing to yield

    def _chunk_messages(self, body: bytes) -> Iterator[FollowedMessage]:
        at = self._pos - len(body) - RECORD_HEADER.size
        try:
            records = _stored_records(body)
            if records is None:  # a compressed chunk: decompressed within its limits
                chunk = Chunk.read(ReadDataStream(io.BytesIO(body)))
                unpacked = decompress(chunk.compression, chunk.data, chunk.uncompressed_size)
                records = breakup_chunk(replace(chunk, compression="", data=unpacked), True)
        except (McapError, CRCValidationError, struct.error, zlib.error, ValueError) as exc:
            raise LogError(
                f"{self.name}: the chunk at byte {at} is damaged ({exc}); the chunks before it "
                "were read"
            ) from None
        self.chunk_count += 1
        for record in records:
            if isinstance(record, Schema):
                self._schemas[record.id] = record.name
            elif isinstance(record, Channel):
                schema = self._schemas.get(record.schema_id, "")
                self._channels[record.id] = (record.topic, schema)
            elif isinstance(record, Message):
                topic, schema = self._channels.get(record.channel_id, ("", ""))
                if not topic:
                    raise LogError(
                        f"{self.name}: a message in the chunk at byte {at} has no channel record"
                    )
                yield FollowedMessage(topic, schema, record)


def _stored_records(body: bytes) -> list[McapRecord] | None:
    """Records of a stored (uncompressed) chunk, CRC-checked; None for a compressed chunk.

    The recorder's chunks are stored (frames are PNG already). Splitting them here, CRC with
    ISA-L and message data sliced out once, costs a third of mcap's record-by-record reader.

    Raises
    ------
    ValueError
        The CRC or a record length does not match.
    """
    _, _, size, crc, name_length = _CHUNK_HEAD.unpack_from(body)
    if name_length:
        return None
    (length,) = _U64.unpack_from(body, _CHUNK_HEAD.size)
    start = _CHUNK_HEAD.size + _U64.size
    view = memoryview(body)[start : start + length]
    if len(view) != length or length != size:
        raise ValueError(f"records of {len(view)} bytes where the chunk says {size}")
    if crc and isal_zlib.crc32(view) != crc:
        raise ValueError("CRC mismatch")
    out: list[McapRecord] = []
    pos = 0
    while pos < length:
        opcode, n = RECORD_HEADER.unpack_from(view, pos)
        pos += RECORD_HEADER.size
        record = view[pos : pos + n]
        pos += n
        if len(record) != n:
            raise ValueError("a record is cut short")
        if opcode == Opcode.MESSAGE:
            channel_id, sequence, log_time, publish_time = _MESSAGE_HEAD.unpack_from(record)
            data = bytes(record[_MESSAGE_HEAD.size :])
            out.append(Message(channel_id, log_time, data, publish_time, sequence))
        elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL):
            kind = Schema if opcode == Opcode.SCHEMA else Channel
            out.append(kind.read(ReadDataStream(io.BytesIO(record))))
    return out
