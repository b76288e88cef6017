"""Walk any MCAP file record by record, checking everything, and keep what is whole.

:class:`LogScan` reads a file (finished, cut short, corrupt, or written by another tool) in file
order and yields every schema, channel, message, metadata and attachment record it can trust,
while it notes each damaged stretch of bytes as a :class:`Damage`:

* chunk CRCs are checked (stored, zstd and lz4 chunks), attachment CRCs too, and each message
  index is compared with the messages of its chunk;
* where a record cannot be read, the scan resynchronises on the next record that checks out
  (a chunk whose CRC matches, a well-formed message index, metadata, ...), so the chunks after
  the damage are read as if nothing happened;
* inside a corrupt or cut-off stored chunk every complete message record is salvaged, walking
  the records from the chunk's start and, where that walk breaks off, at the offsets its message
  indexes give; a salvaged message of a JSON channel whose data does not parse (the damage
  fell inside it) is dropped and counted (:attr:`Damage.dropped`);
* records outside chunks (unchunked files), metadata and attachments are read wherever they lie;
  the summary section is read too (schemas and channels missing from the data section are taken
  from it) and its CRC checked.

The scan never raises for damage (only for a file that is not MCAP at all) and never loops:
each step moves forward in the file.
"""

from __future__ import annotations

import io
import json
import mmap
import os
import re
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import IO

from isal import isal_zlib
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    Channel,
    Chunk,
    ChunkIndex,
    Footer,
    Header,
    McapRecord,
    Message,
    Metadata,
    Schema,
    Statistics,
)

from data_schemas.closing import Closing
from data_schemas.errors import LogError, NotMcapError
from data_schemas.inputs import open_input
from data_schemas.mcap.compression import COMPRESSIONS, DecompressionError, decompress
from data_schemas.mcap.layout import (
    CHUNK_FIELDS,
    INDEX_ENTRY,
    INDEX_FIELDS,
    MAGIC,
    MESSAGE_FIELDS,
    MESSAGE_HEADER,
    RECORD_HEADER,
)

_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
#: Records that may stand at the top level of an MCAP file (the rest: damage or private).
_TOP_LEVEL = frozenset(int(o) for o in Opcode)
#: A plausible record start: a known opcode and a length below 2**40 (used to resynchronise).
_CANDIDATE = re.compile(rb"[\x01-\x0f](?=.{5}\x00\x00\x00)", re.DOTALL)
_SUMMARY_OPCODES = frozenset(
    {
        Opcode.CHUNK_INDEX,
        Opcode.ATTACHMENT_INDEX,
        Opcode.METADATA_INDEX,
        Opcode.STATISTICS,
        Opcode.SUMMARY_OFFSET,
    }
)
_PARSE_ERRORS = (
    McapError,
    struct.error,
    UnicodeDecodeError,
    ValueError,
    EOFError,
    KeyError,
    IndexError,
)

Record = Schema | Channel | Message | Metadata | Attachment


@dataclass
class Damage:
    """One damaged stretch of a log.

    Attributes
    ----------
    start, end : int
        File offsets of the damaged bytes (``end`` exclusive).
    what : str
        What lay there: ``"chunk"``, ``"cut chunk"`` (the file ends inside it),
        ``"message index"``, ``"summary"``, ``"record"``, ``"attachment"``, ``"file end"``.
    detail : str
        How it is damaged (e.g. ``"CRC mismatch"``).
    start_ns, end_ns : int or None
        Log-time range the damaged chunk covered (from its header or its salvaged messages).
    topics : set of str
        Topics of the messages it held (as far as known).
    kept : int
        Messages salvaged from it (complete message records whose data decodes as their
        channel's encoding).
    dropped : int
        Complete message records of it whose data does not decode (JSON channels): left out.
    expected : int or None
        Messages its message indexes list, None if they are not known.
    loses_data : bool
        False for damage that costs no message, metadata or attachment (an index or summary,
        rebuilt by ``bslam recover``).
    """

    start: int
    end: int
    what: str
    detail: str
    start_ns: int | None = None
    end_ns: int | None = None
    topics: set[str] = field(default_factory=set)
    kept: int = 0
    dropped: int = 0
    expected: int | None = None
    loses_data: bool = True

    def describe(self, *, salvaged: bool = True) -> str:
        """One line: where, what, which time range and topics, what was kept.

        ``salvaged=False``: how many messages it held instead (for a part skipped whole).
        """
        text = f"{self.what} at bytes {self.start}-{self.end}: {self.detail}"
        if self.start_ns is not None and self.end_ns is not None:
            text += f", log time {self.start_ns / 1e9:.3f}-{self.end_ns / 1e9:.3f} s"
        if self.topics:
            text += f", topics {', '.join(sorted(self.topics))}"
        if self.what in ("chunk", "cut chunk") and salvaged:
            total = "" if self.expected is None else f" of {self.expected}"
            text += f"; {self.kept}{total} messages salvaged"
            if self.dropped:
                text += f" ({self.dropped} more dropped: their data does not decode)"
        elif self.what in ("chunk", "cut chunk") and self.expected is not None:
            text += f"; {self.expected} messages"
        return text


@dataclass
class _Pending:
    """A damaged chunk whose message indexes (which follow it) are still being collected."""

    damage: Damage
    records_start: int
    records_end: int
    walked: set[int]
    index: dict[int, list[tuple[int, int]]] = field(default_factory=dict)


class LogScan(Closing):
    """Scan one MCAP file (see module docstring); iterate :meth:`records` once.

    Parameters
    ----------
    source : str, os.PathLike or binary stream
        The file (mapped into memory, not read), or a stream (read whole).
    salvage : bool
        Yield the complete messages of damaged chunks (False: skip damaged chunks whole, as
        ``--skip-corrupt`` does, since one of their messages may hold the damaged byte).

    Raises
    ------
    LogError
        The file cannot be opened.
    NotMcapError
        It does not start with the MCAP magic (nor with a readable header record).

    Attributes (complete once :meth:`records` is exhausted)
    -------------------------------------------------------
    damage : list of Damage
        Every damaged stretch, in file order.
    finished : bool
        The file ends with a footer and the closing magic.
    has_summary : bool
        A summary section was found (and its CRC, if any, matched).
    chunks : int
        Chunks read whole (CRC checked).
    compressions : set of str
        Compressions of those chunks (``""`` for stored).
    messages : int
        Messages yielded.
    schemas, channels : dict
        Every schema and channel seen (data and summary sections), by id.
    statistics : Statistics or None
        The summary's statistics record, if any.
    chunk_indexes : list of ChunkIndex
        The summary's chunk indexes.
    header : Header or None
        The header record.
    trailing_bytes : int
        Bytes after the last record that could be read whole (a cut-off end), 0 if none.
    """

    def __init__(self, source: str | os.PathLike[str] | IO[bytes], *, salvage: bool = True) -> None:
        self._salvage = salvage
        self._data: bytes | mmap.mmap
        if not isinstance(source, str | os.PathLike):
            self.name = str(getattr(source, "name", "<stream>"))
            source.seek(0)
            self._data = source.read()
        else:
            self.name = os.fspath(source)
            try:
                with open_input(self.name, what="log", error=LogError) as file:
                    size = os.fstat(file.fileno()).st_size
                    self._data = (
                        mmap.mmap(file.fileno(), 0, access=mmap.ACCESS_READ) if size else b""
                    )
            except OSError as exc:
                raise LogError(f"cannot open log {self.name}: {exc.strerror or exc}") from None
        self._size = len(self._data)
        self.damage: list[Damage] = []
        self.finished = False
        self.has_summary = False
        self.chunks = 0
        self.compressions: set[str] = set()
        self.messages = 0
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self.statistics: Statistics | None = None
        self.chunk_indexes: list[ChunkIndex] = []
        self.header: Header | None = None
        self.trailing_bytes = 0
        self._orphans: dict[int, int] = {}
        self._pending: _Pending | None = None
        self._last_chunk: tuple[int, int, dict[int, list[tuple[int, int]]]] | None = None
        self._summary_start: int | None = None
        self._summary_schemas: dict[int, Schema] = {}
        self._summary_channels: dict[int, Channel] = {}
        self._magic_ok = self._data[: len(MAGIC)] == MAGIC
        if not self._magic_ok and not self._header_at(len(MAGIC)):
            self.close()
            raise NotMcapError(f"{self.name} is not an MCAP file (bad magic bytes)")

    # ------------------------------------------------------------------ public API
    @property
    def damaged(self) -> bool:
        """Any damage found (so far)."""
        return bool(self.damage)

    @property
    def lost_data(self) -> bool:
        """Some damage cost messages, metadata or attachments (or may have)."""
        return any(d.loses_data for d in self.damage)

    @property
    def orphan_messages(self) -> int:
        """Messages dropped because their channel record was nowhere to be found."""
        return sum(self._orphans.values())

    def records(self) -> Iterator[Record]:
        """Every trustworthy schema, channel, message, metadata and attachment, in file order.

        Schema and channel records are yielded once per id (the first whole copy).
        """
        if not self._magic_ok:
            self.damage.append(Damage(0, len(MAGIC), "magic", "bad magic bytes", loses_data=False))
        self._read_summary_definitions()
        pos = len(MAGIC)
        end = self._size
        #: the last record read whole: opcode, start, end, summary start before it
        previous: tuple[int, int, int, int | None] | None = None
        while pos < end:
            if self._is_closing_magic(pos):
                break
            step = self._record_at(pos)
            if step is None:
                yield from self._settle()
                nxt = self._resync(pos + 1)
                yield from self._damaged_region(pos, nxt)
                pos, previous = nxt, None
                continue
            opcode, body, stop = step
            if opcode != Opcode.MESSAGE_INDEX:
                yield from self._settle()
            elif self._follows_no_chunk(previous):
                # message indexes follow chunks only: the record before was a chunk whose
                # opcode byte is damaged (it read as another, or a private, record)
                assert previous is not None
                self._summary_start = previous[3]
                yield from self._damaged_region(
                    previous[1], previous[2], detail="its record type byte is damaged"
                )
            summary_start = self._summary_start
            try:
                yield from self._handle(opcode, pos, body, stop)
            except _PARSE_ERRORS as exc:
                yield from self._settle()
                nxt = self._resync(pos + 1)
                yield from self._damaged_region(pos, nxt, detail=f"unreadable ({exc})")
                pos, previous = nxt, None
                continue
            pos, previous = stop, (opcode, pos, stop, summary_start)
        yield from self._settle()
        if self._orphans:
            lost = ", ".join(f"channel {c}: {n}" for c, n in sorted(self._orphans.items()))
            self.damage.append(
                Damage(0, 0, "channels", f"messages without a channel record dropped ({lost})")
            )

    def _follows_no_chunk(self, previous: tuple[int, int, int, int | None] | None) -> bool:
        return (
            previous is not None
            and previous[0] not in (Opcode.CHUNK, Opcode.MESSAGE_INDEX)
            and self._pending is None
            and self._last_chunk is None
        )

    def close(self) -> None:
        """Release the file."""
        if isinstance(self._data, mmap.mmap):
            self._data.close()

    # ------------------------------------------------------------------ framing
    def _is_closing_magic(self, pos: int) -> bool:
        return pos + len(MAGIC) == self._size and self._data[pos:] == MAGIC

    def _header_at(self, pos: int) -> bool:
        step = self._record_at(pos)
        return step is not None and step[0] == Opcode.HEADER

    def _record_at(self, pos: int) -> tuple[int, int, int] | None:
        """(opcode, body start, record end) of a record that fits in the file, else None."""
        if pos + RECORD_HEADER.size > self._size:
            return None
        opcode, length = RECORD_HEADER.unpack_from(self._data, pos)
        body = pos + RECORD_HEADER.size
        if length > self._size - body or (opcode not in _TOP_LEVEL and opcode < 0x80):
            return None
        return opcode, body, body + length

    def _resync(self, start: int) -> int:
        """Offset of the next record at or after ``start`` that checks out (else file end)."""
        for match in _CANDIDATE.finditer(self._data, start):
            pos = match.start()
            if self._is_closing_magic(pos) or self._verified(pos):
                return pos
        if self._size - len(MAGIC) >= start and self._data[-len(MAGIC) :] == MAGIC:
            return self._size - len(MAGIC)
        return self._size

    def _verified(self, pos: int) -> bool:
        """A record at ``pos`` fits and its structure (and CRC if it has one) checks out."""
        step = self._record_at(pos)
        if step is None:
            return False
        opcode, body, stop = step
        data = self._data
        try:
            if opcode == Opcode.CHUNK:
                return self._chunk_fields(body, stop) is not None and self._chunk_ok(body, stop)
            if opcode == Opcode.MESSAGE_INDEX:
                size: int = INDEX_FIELDS.unpack_from(data, body)[1]
                return stop - body == INDEX_FIELDS.size + size and size % INDEX_ENTRY.size == 0
            if opcode == Opcode.DATA_END:
                return stop - body == 4
            if opcode == Opcode.FOOTER:
                return stop - body == 20 and stop + len(MAGIC) == self._size
            if opcode == Opcode.ATTACHMENT:
                return self._attachment_crc_ok(body, stop)
            if opcode in (Opcode.METADATA, Opcode.SCHEMA, Opcode.CHANNEL, Opcode.HEADER):
                return _consumes(opcode, data[body:stop])
            if opcode in _SUMMARY_OPCODES:
                return _consumes(opcode, data[body:stop])
        except _PARSE_ERRORS:
            return False
        return False

    # ------------------------------------------------------------------ records
    def _handle(self, opcode: int, pos: int, body: int, stop: int) -> Iterator[Record]:
        data = self._data
        if opcode == Opcode.CHUNK:
            yield from self._chunk(pos, body, stop)
        elif opcode == Opcode.MESSAGE_INDEX:
            self._message_index(pos, body, stop)
        elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL):
            yield from self._definition(_parse(opcode, data[body:stop]))  # type: ignore[arg-type]
        elif opcode == Opcode.MESSAGE:
            yield from self._message(body, stop)
        elif opcode == Opcode.METADATA:
            yield _parse(opcode, data[body:stop])  # type: ignore[misc]
        elif opcode == Opcode.ATTACHMENT:
            if not self._attachment_crc_ok(body, stop):
                self.damage.append(Damage(pos, stop, "attachment", "CRC mismatch"))
            else:
                yield _parse(opcode, data[body:stop])  # type: ignore[misc]
        elif opcode == Opcode.HEADER:
            self.header = _parse(opcode, data[body:stop])  # type: ignore[assignment]
        elif opcode == Opcode.DATA_END:
            self._summary_start = stop
        elif opcode == Opcode.FOOTER:
            self._footer(pos, body, stop)
        elif opcode in _SUMMARY_OPCODES:
            self._summary_start = pos if self._summary_start is None else self._summary_start
            record = _parse(opcode, data[body:stop])
            if isinstance(record, Statistics):
                self.statistics = record
            elif isinstance(record, ChunkIndex):
                self.chunk_indexes.append(record)
        # opcodes >= 0x80 are private records: skipped by their length

    def _definition(self, record: Schema | Channel) -> Iterator[Record]:
        if isinstance(record, Schema):
            if record.id not in self.schemas:
                self.schemas[record.id] = record
                yield record
        elif record.id not in self.channels:
            self.channels[record.id] = record
            yield record

    def _message(self, body: int, stop: int) -> Iterator[Record]:
        message = _message_at(self._data, body - RECORD_HEADER.size, stop)
        if message is None:
            raise ValueError("malformed message record")
        yield from self._admit(message)

    def _admit(self, message: Message) -> Iterator[Record]:
        """The message (after its schema and channel, if only the summary defines them)."""
        channel_id = message.channel_id
        if channel_id not in self.channels and channel_id in self._summary_channels:
            channel = self._summary_channels[channel_id]
            schema = self._summary_schemas.get(channel.schema_id)
            if schema is not None:
                yield from self._definition(schema)
            yield from self._definition(channel)
        if channel_id in self.channels:
            self.messages += 1
            yield message
        else:
            self._orphans[channel_id] = self._orphans.get(channel_id, 0) + 1

    def _read_summary_definitions(self) -> None:
        """Schemas and channels of the summary section (the footer says where), if readable."""
        tail = RECORD_HEADER.size + 20 + len(MAGIC)
        at = self._size - tail
        if at < len(MAGIC) or self._data[-len(MAGIC) :] != MAGIC:
            return
        try:
            if self._record_at(at) != (Opcode.FOOTER, at + RECORD_HEADER.size, at + tail - 8):
                return
            footer = _parse(Opcode.FOOTER, self._data[at + RECORD_HEADER.size : at + tail - 8])
            pos = footer.summary_start  # type: ignore[attr-defined]
            while 0 < pos < at:
                step = self._record_at(pos)
                if step is None:
                    return
                opcode, body, stop = step
                if opcode in (Opcode.SCHEMA, Opcode.CHANNEL):
                    record = _parse(opcode, self._data[body:stop])
                    if isinstance(record, Schema):
                        self._summary_schemas[record.id] = record
                    elif isinstance(record, Channel):
                        self._summary_channels[record.id] = record
                pos = stop
        except _PARSE_ERRORS:
            return

    def _footer(self, pos: int, body: int, stop: int) -> None:
        footer: Footer = _parse(Opcode.FOOTER, self._data[body:stop])  # type: ignore[assignment]
        self.finished = stop + len(MAGIC) == self._size and self._data[stop:] == MAGIC
        if not self.finished:
            self.damage.append(
                Damage(stop, self._size, "file end", "no closing magic", loses_data=False)
            )
        start = footer.summary_start
        if start == 0:
            return
        if self._summary_start is None or start > pos:
            self.damage.append(
                Damage(pos, stop, "summary", "footer points nowhere", loses_data=False)
            )
            return
        if footer.summary_crc:
            crc = zlib.crc32(self._data[start : pos + RECORD_HEADER.size + 16])
            if crc != footer.summary_crc:
                self.damage.append(Damage(start, pos, "summary", "CRC mismatch", loses_data=False))
                return
        self.has_summary = True

    def _attachment_crc_ok(self, body: int, stop: int) -> bool:
        record = self._data[body:stop]
        _parse(Opcode.ATTACHMENT, record)  # structure
        crc: int = _U32.unpack_from(record, len(record) - 4)[0]
        return crc == 0 or zlib.crc32(record[:-4]) == crc

    # ------------------------------------------------------------------ chunks
    def _chunk_fields(self, body: int, stop: int) -> tuple[int, int, int, int, str] | None:
        """(start ns, end ns, CRC, records start, compression) of a well-framed chunk."""
        data = self._data
        start_ns, end_ns, _, crc = CHUNK_FIELDS.unpack_from(data, body)
        at = body + CHUNK_FIELDS.size
        (n,) = _U32.unpack_from(data, at)
        if n > 16:
            return None
        compression = bytes(data[at + 4 : at + 4 + n]).decode()
        at += 4 + n
        (records_length,) = _U64.unpack_from(data, at)
        at += 8
        if compression not in COMPRESSIONS or at + records_length != stop:
            return None
        return start_ns, end_ns, crc, at, compression

    def _chunk_ok(self, body: int, stop: int) -> bool:
        fields = self._chunk_fields(body, stop)
        if fields is None:
            return False
        if fields[4] == "":
            crc = fields[2]
            return crc == 0 or isal_zlib.crc32(self._data[fields[3] : stop]) == crc
        return self._decompressed(body, stop) is not None

    def _decompressed(self, body: int, stop: int) -> bytes | None:
        """The records of a compressed chunk, None if they do not decompress to its CRC."""
        fields = self._chunk_fields(body, stop)
        if fields is None:
            return None
        _, _, crc, records_at, compression = fields
        size = _U64.unpack_from(self._data, body + 16)[0]
        try:
            with memoryview(self._data) as whole, whole[records_at:stop] as payload:
                records = decompress(compression, payload, size)
        except DecompressionError:
            return None
        return records if crc == 0 or isal_zlib.crc32(records) == crc else None

    def _chunk(self, pos: int, body: int, stop: int) -> Iterator[Record]:
        fields = self._chunk_fields(body, stop)
        if fields is None:
            raise ValueError("malformed chunk header")
        start_ns, end_ns, crc, records_at, compression = fields
        records: bytes | mmap.mmap = self._data
        if compression == "":
            whole = crc == 0 or isal_zlib.crc32(self._data[records_at:stop]) == crc
            base, length = records_at, stop - records_at
        else:
            unpacked = self._decompressed(body, stop)
            whole = unpacked is not None
            records, base, length = unpacked or b"", 0, len(unpacked or b"")
        if not whole:
            damage = Damage(pos, stop, "chunk", "CRC mismatch", start_ns, end_ns)
            self.damage.append(damage)
            walked: set[int] = set()
            if compression == "":
                yield from self._walk(records_at, stop, damage, walked)
            else:
                damage.detail = f"{compression} data does not decompress to its CRC"
            self._pending = _Pending(damage, records_at, stop, walked)
            return
        self.chunks += 1
        self.compressions.add(compression)
        counts: dict[int, list[tuple[int, int]]] = {}
        yield from self._inner(records, base, base + length, counts)
        self._last_chunk = (pos, stop, counts)
        times = [t for entries in counts.values() for t, _ in entries]
        size = _U64.unpack_from(self._data, body + 16)[0]
        if (times and (min(times), max(times)) != (start_ns, end_ns)) or size != length:
            self.damage.append(
                Damage(pos, stop, "chunk header", "times or size disagree with its records")
            )
            self.damage[-1].loses_data = False

    def _inner(
        self,
        data: bytes | mmap.mmap,
        start: int,
        stop: int,
        seen: dict[int, list[tuple[int, int]]],
    ) -> Iterator[Record]:
        """Records of a whole chunk; ``seen`` gets channel -> [(log time, offset)]."""
        pos = start
        while pos < stop:
            opcode, length = RECORD_HEADER.unpack_from(data, pos)
            body = pos + RECORD_HEADER.size
            end = body + length
            if opcode == Opcode.MESSAGE:
                message = _message_at(data, pos, end)
                if message is None:
                    raise ValueError("malformed message record in a chunk")
                yield from self._admit(message)
                seen.setdefault(message.channel_id, []).append((message.log_time, pos - start))
            elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL):
                yield from self._definition(_parse(opcode, bytes(data[body:end])))  # type: ignore[arg-type]
            else:  # a chunk holds schemas, channels and messages only (32 MiB of zeros: not)
                raise ValueError(f"a record of type {opcode:#04x} inside a chunk")
            pos = end

    def _message_index(self, pos: int, body: int, stop: int) -> None:
        channel_id, size = INDEX_FIELDS.unpack_from(self._data, body)
        if stop - body != INDEX_FIELDS.size + size or size % INDEX_ENTRY.size:
            raise ValueError("malformed message index")
        first = body + INDEX_FIELDS.size
        entries = list(INDEX_ENTRY.iter_unpack(self._data[first : first + size]))
        if self._pending is not None:
            self._pending.index[channel_id] = entries
            return
        if self._last_chunk is None:
            return  # an index with no chunk before it: nothing to check it against
        seen = self._last_chunk[2].get(channel_id, [])
        if sorted(entries) != sorted(seen):
            self.damage.append(
                Damage(
                    pos,
                    stop,
                    "message index",
                    f"does not match its chunk (channel {channel_id})",
                    loses_data=False,
                )
            )

    def _settle(self) -> Iterator[Record]:
        """Finish a pending damaged chunk: salvage messages at its index's offsets."""
        self._last_chunk = None
        pending, self._pending = self._pending, None
        if pending is None:
            return
        damage = pending.damage
        if pending.index:
            damage.expected = sum(len(e) for e in pending.index.values())
            damage.topics |= {self.channels[c].topic for c in pending.index if c in self.channels}
        for channel_id, entries in pending.index.items():
            for log_time, offset in entries:
                at = pending.records_start + offset
                if at in pending.walked or at >= pending.records_end:
                    continue
                message = _message_at(self._data, at, pending.records_end)
                if message is None or (message.channel_id, message.log_time) != (
                    channel_id,
                    log_time,
                ):
                    continue
                pending.walked.add(at)
                yield from self._salvaged(message, damage)

    def _walk(self, start: int, stop: int, damage: Damage, walked: set[int]) -> Iterator[Record]:
        """Complete records of a damaged stored chunk, from its start until the walk breaks."""
        data = self._data
        pos = start
        while pos + RECORD_HEADER.size <= stop:
            opcode, length = RECORD_HEADER.unpack_from(data, pos)
            end = pos + RECORD_HEADER.size + length
            if end > stop:
                break
            try:
                if opcode == Opcode.MESSAGE:
                    message = _message_at(data, pos, end)
                    if message is None:
                        break
                    walked.add(pos)
                    yield from self._salvaged(message, damage)
                elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL):
                    record = _parse(opcode, bytes(data[pos + RECORD_HEADER.size : end]))
                    yield from self._definition(record)  # type: ignore[arg-type]
                else:
                    break
            except _PARSE_ERRORS:
                break
            pos = end

    def _salvaged(self, message: Message, damage: Damage) -> Iterator[Record]:
        if not self._salvage:
            return
        channel = self.channels.get(message.channel_id) or self._summary_channels.get(
            message.channel_id
        )
        if channel is not None and not _decodes(channel.message_encoding, message.data):
            damage.dropped += 1  # a damaged byte inside the record: not a message to keep
            return
        before = self.messages
        yield from self._admit(message)
        if self.messages == before:
            return
        damage.kept += 1
        damage.topics.add(self.channels[message.channel_id].topic)
        if damage.start_ns is None or damage.end_ns is None:
            damage.start_ns = damage.end_ns = message.log_time
        else:
            damage.start_ns = min(damage.start_ns, message.log_time)
            damage.end_ns = max(damage.end_ns, message.log_time)

    def _damaged_region(self, start: int, stop: int, detail: str = "") -> Iterator[Record]:
        """Bytes between a record that cannot be read and the next one that can."""
        data = self._data
        if stop <= start:
            return
        cut = stop == self._size or (stop == self._size - len(MAGIC) and not self.finished)
        looks_like_chunk = data[start] == Opcode.CHUNK or self._chunk_shaped(start, stop)
        if not looks_like_chunk:
            what = "summary" if self._summary_start is not None else "record"
            if data[start] == Opcode.MESSAGE_INDEX:
                what = "message index"
            elif stop - start == RECORD_HEADER.size + 4 and self._verified(stop):
                what = "data end"  # its 13 bytes hold no data
            loses = what == "record"
            torn_end = cut and stop == self._size and start > len(MAGIC)
            if torn_end and what in ("record", "message index"):
                self.trailing_bytes = stop - start
                what, detail = "file end", detail or "cut off inside a record"
            self.damage.append(
                Damage(start, stop, what, detail or "unreadable bytes", loses_data=loses)
            )
            return
        damage = Damage(
            start,
            stop,
            "cut chunk" if cut and stop == self._size else "chunk",
            detail or ("the file ends inside it" if cut else "unreadable chunk header"),
        )
        if cut and stop == self._size:
            self.trailing_bytes = stop - start
        self.damage.append(damage)
        body = start + RECORD_HEADER.size
        records_at = body + CHUNK_FIELDS.size + 4 + 8
        if body + CHUNK_FIELDS.size + 4 <= stop:
            start_ns, end_ns, _, _ = CHUNK_FIELDS.unpack_from(data, body)
            (n,) = _U32.unpack_from(data, body + CHUNK_FIELDS.size)
            if n in (4, 3) and bytes(data[body + CHUNK_FIELDS.size + 4 :][:n]) in (
                b"zstd",
                b"lz4",
            ):
                damage.detail += " (compressed: nothing inside can be salvaged)"
                return
            if start_ns <= end_ns and end_ns - start_ns < 10**13:
                damage.start_ns, damage.end_ns = start_ns, end_ns
        walked: set[int] = set()
        yield from self._walk(records_at, stop, damage, walked)
        self._pending = _Pending(damage, records_at, stop, walked)

    def _chunk_shaped(self, start: int, stop: int) -> bool:
        """The damaged bytes start like a stored chunk whose opcode byte was hit."""
        records_at = start + RECORD_HEADER.size + CHUNK_FIELDS.size + 4 + 8
        return records_at + MESSAGE_HEADER.size <= stop and (
            self._data[records_at] in (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.MESSAGE)
            and _U32.unpack_from(self._data, records_at - 12)[0] == 0
        )


def _decodes(encoding: str, data: bytes) -> bool:
    """Message ``data`` decodes as ``encoding`` (checked for JSON; other encodings: True)."""
    if encoding != "json":
        return True
    try:
        json.loads(data)
    except (ValueError, RecursionError):  # UnicodeDecodeError and JSONDecodeError included
        return False
    return True


def _message_at(data: bytes | mmap.mmap, pos: int, limit: int) -> Message | None:
    """The message record at ``pos`` if it is one and ends by ``limit``, else None."""
    if pos + MESSAGE_HEADER.size > limit:
        return None
    opcode, length, channel, sequence, log_time, publish_time = MESSAGE_HEADER.unpack_from(
        data, pos
    )
    end = pos + RECORD_HEADER.size + length
    if opcode != Opcode.MESSAGE or length < MESSAGE_FIELDS or end > limit:
        return None
    return Message(
        channel_id=channel,
        sequence=sequence,
        log_time=log_time,
        publish_time=publish_time,
        data=bytes(data[pos + MESSAGE_HEADER.size : end]),
    )


_CLASSES: dict[int, type[McapRecord]] = {
    Opcode.HEADER: Header,
    Opcode.FOOTER: Footer,
    Opcode.SCHEMA: Schema,
    Opcode.CHANNEL: Channel,
    Opcode.CHUNK: Chunk,
    Opcode.METADATA: Metadata,
    Opcode.ATTACHMENT: Attachment,
    Opcode.STATISTICS: Statistics,
    Opcode.CHUNK_INDEX: ChunkIndex,
}


def _parse(opcode: int, body: bytes | mmap.mmap) -> McapRecord:
    """One record from its body (summary records other than the above: not parsed)."""
    cls = _CLASSES.get(opcode)
    if cls is None:
        return McapRecord()
    stream = ReadDataStream(io.BytesIO(bytes(body)))
    record: McapRecord = cls.read(stream)  # type: ignore[attr-defined]
    return record


def _consumes(opcode: int, body: bytes | mmap.mmap) -> bool:
    """The body parses as its record type and nothing is left over."""
    cls = _CLASSES.get(opcode)
    if cls is None:
        return False
    raw = io.BytesIO(bytes(body))
    cls.read(ReadDataStream(raw))  # type: ignore[attr-defined]
    return raw.tell() == len(body)
