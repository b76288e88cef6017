"""Read chosen channels of a finished log through its message indexes, each chunk checked once.

mcap's indexed reader parses every record of every chunk that holds a wanted channel, through
thousands of small reads, and does it again on each pass. Every chunk of a log the recorder (or
mcap's ``Writer``) writes is followed by one message index per channel (log time, offset in the
chunk's records), so :class:`LogIndex` knows where each message lies without reading a chunk.

A pass (:meth:`LogIndex.messages`) reads, in mcap's log-time order (log time, then position in
the file), only the chunks that hold a wanted message. Each chunk is checked by a worker thread,
up to two chunks ahead of the caller, so that the CRC and the decompression (which release the GIL)
run on a second core while the caller copies out the messages of the chunk before:

* a stored chunk is checked where it lies in the mapped file (its CRC, then a walk over its
  record headers); each wanted message is then copied once, from the mapping, by the caller;
* a compressed chunk (zstd, lz4) is decompressed once, its CRC taken over the uncompressed
  records, which are walked once; messages are cut from them.

No message of a chunk is handed out before that chunk has passed its checks: its CRC, and its
message indexes against the records it holds. A damaged chunk raises :class:`CorruptChunksError`
when the pass reaches it (messages of earlier chunks may have been handed out by then). A stored
chunk checked once is trusted by later passes, which only walk its record headers. Logs without
message indexes are left to the checking scan: :meth:`LogIndex.of` returns None.
"""

from __future__ import annotations

import contextlib
import mmap
import os
import struct
import threading
from collections.abc import Collection, Container, Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import IO

from isal import isal_zlib
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import ChunkIndex
from mcap.summary import Summary

from data_schemas.mcap.compression import COMPRESSIONS, DecompressionError, decompress
from data_schemas.mcap.layout import (
    CHUNK_FIELDS,
    INDEX_ENTRY,
    INDEX_FIELDS,
    MESSAGE_FIELDS,
    MESSAGE_HEADER,
    RECORD_HEADER,
    STORED_CHUNK_HEADER,
)

#: Threads that check chunks (CRC, decompression, walk) for a pass, beside the caller's: one
#: (measured on 2 cores: a second one competes with the caller and costs more than it saves).
_LOAD_THREADS = 1
#: One message's fields: channel id, sequence, log time (ns), publish time (ns), data (what a
#: pass yields; no mcap ``Message`` object per message).
MessageFields = tuple[int, int, int, int, bytes]
#: Chunks checked ahead of the one the caller reads from.
_AHEAD = 2
#: Where one message lies: log time, file offset of its chunk, offset in the chunk's records,
#: channel id. Tuples sort in mcap's log-time order (log time, then position in the file).
_Place = tuple[int, int, int, int]
#: A message as a message index lists it: offset in the chunk's records, channel id, log time.
_Entry = tuple[int, int, int]
#: A message record's head: length, channel id, sequence, log time, publish time.
_Head = tuple[int, int, int, int, int]
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
#: The records a chunk may hold (MCAP specification).
_IN_CHUNK = frozenset({Opcode.SCHEMA, Opcode.CHANNEL, Opcode.MESSAGE})


class DamagedLogError(McapError):
    """An index entry does not point at a whole message of its channel."""


class CorruptChunksError(DamagedLogError):
    """Chunks a read needs fail their CRC or disagree with their message indexes."""

    def __init__(self, chunks: list[tuple[ChunkIndex, str]]) -> None:
        super().__init__(
            "; ".join(f"chunk at byte {c.chunk_start_offset}: {problem}" for c, problem in chunks)
        )
        self.chunks = chunks


class _Damaged(Exception):
    """Why a chunk fails its checks (raised inside a load, reported as CorruptChunksError)."""


class LogIndex:
    """Where every message of a finished log lies (see :meth:`of`), and reading them there.

    Parameters
    ----------
    stream : binary file (seekable)
        The open log; read, never closed here.
    places : dict channel id -> list of (log time, chunk offset, offset, channel id)
        Every message's place, from the log's message indexes.
    chunks : sequence of ChunkIndex
        The summary's chunk indexes.
    """

    def __init__(
        self,
        stream: IO[bytes],
        places: dict[int, list[_Place]],
        chunks: Sequence[ChunkIndex] = (),
    ) -> None:
        self._stream = stream
        self._places = places
        self._chunks = {c.chunk_start_offset: c for c in chunks}
        #: per chunk, every message its indexes list, sorted
        self._entries: dict[int, list[_Entry]] = {c: [] for c in self._chunks}
        for channel_places in places.values():
            for log_time_ns, chunk_at, offset, channel_id in channel_places:
                self._entries.setdefault(chunk_at, []).append((offset, channel_id, log_time_ns))
        for entries in self._entries.values():
            entries.sort()
        self._checked: set[int] = set()  # offsets of chunks that checked out
        self._lock = threading.Lock()
        self._mapping: mmap.mmap | None = None
        self._view: memoryview | None = None  # the mapped file, for checking stored chunks

    @property
    def channel_ids(self) -> list[int]:
        """Channels with indexed messages."""
        return list(self._places)

    @classmethod
    def of(cls, stream: IO[bytes], summary: Summary | None) -> LogIndex | None:
        """The index of a log whose chunks are all indexed, else None.

        Reads the message indexes after each chunk (small records) and nothing else. None when
        chunks or message indexes are missing, when a chunk's compression is not MCAP's, or when
        the indexes do not count every message of the summary's statistics.
        """
        if summary is None or not summary.chunk_indexes:
            return None
        if any(
            c.compression not in COMPRESSIONS or not c.message_index_length
            for c in summary.chunk_indexes
        ):
            return None
        places: dict[int, list[_Place]] = {}
        for chunk in summary.chunk_indexes:
            chunk_at = chunk.chunk_start_offset
            stream.seek(chunk.chunk_start_offset + chunk.chunk_length)
            block = stream.read(chunk.message_index_length)
            pos = 0
            while pos + RECORD_HEADER.size + INDEX_FIELDS.size <= len(block):
                opcode, length = RECORD_HEADER.unpack_from(block, pos)
                body = pos + RECORD_HEADER.size
                if opcode == Opcode.MESSAGE_INDEX:
                    channel_id, size = INDEX_FIELDS.unpack_from(block, body)
                    first = body + INDEX_FIELDS.size
                    places.setdefault(channel_id, []).extend(
                        (log_time_ns, chunk_at, offset, channel_id)
                        for log_time_ns, offset in INDEX_ENTRY.iter_unpack(
                            block[first : first + size]
                        )
                    )
                pos = body + length
        counted = sum(len(p) for p in places.values())
        if summary.statistics is None or counted != summary.statistics.message_count:
            return None
        return cls(stream, places, summary.chunk_indexes)

    def verify(self, chunks: Collection[int] | None = None) -> list[tuple[ChunkIndex, str]]:
        """Chunks that fail their CRC or whose message indexes disagree with their records,
        each with what is wrong.

        ``chunks``: file offsets of the chunks to check (default all); each chunk is checked
        once.
        """
        todo = [c for c in (self._chunks if chunks is None else chunks) if c not in self._checked]
        results = [self._load(chunk_at).problem for chunk_at in todo]
        bad = []
        for chunk_at, problem in zip(todo, results, strict=True):
            if problem:
                bad.append((self._chunks[chunk_at], problem))
            else:
                self._checked.add(chunk_at)
        return bad

    def channels_in(self, chunk: ChunkIndex) -> set[int]:
        """Channel ids with messages in ``chunk``."""
        return {channel for _, channel, _ in self._entries.get(chunk.chunk_start_offset, ())}

    def close(self) -> None:
        """Release the file's mapping (the stream stays open: it is the caller's).

        A pass still under way (a caller's error left its generator open, its checking thread
        still running) keeps the pages it uses: they are unmapped once it lets go.
        """
        view, mapping = self._view, self._mapping
        self._view = self._mapping = None
        with contextlib.suppress(BufferError):
            if view is not None:
                view.release()
            if mapping is not None:
                mapping.close()

    def fields(
        self,
        channel_ids: Collection[int],
        *,
        start_ns: int | None = None,
        end_ns: int | None = None,
        publish_times_ns: Container[int] | None = None,
    ) -> Iterator[MessageFields]:
        """The fields of the messages of ``channel_ids`` with ``start_ns <= log_time < end_ns``,
        in log-time order: (channel id, sequence, log time, publish time, data).

        ``publish_times_ns``, if given, keeps only messages whose publish time is in it (in a
        stored chunk, the others' data is not read for them).

        Raises
        ------
        CorruptChunksError
            A chunk this pass reads is damaged (raised before any of its messages is yielded).
        DamagedLogError
            An index entry points outside the file or at something else than its message.
        """
        wanted = sorted(
            p
            for c in channel_ids
            for p in self._places.get(c, ())
            if (start_ns is None or p[0] >= start_ns) and (end_ns is None or p[0] < end_ns)
        )
        order = list(dict.fromkeys(p[1] for p in wanted))  # chunks, in order of first need
        rank = {chunk_at: i for i, chunk_at in enumerate(order)}
        left: dict[int, int] = {}
        for _, chunk_at, _, _ in wanted:
            left[chunk_at] = left.get(chunk_at, 0) + 1
        loaded: dict[int, _Loaded] = {}
        pending: dict[int, Future[_Loaded]] = {}
        submitted = 0
        data = self._data()
        with ThreadPoolExecutor(max_workers=_LOAD_THREADS) as pool:
            try:
                for log_time_ns, chunk_at, offset, channel_id in wanted:
                    chunk = loaded.get(chunk_at)
                    if chunk is None:
                        while submitted < min(len(order), rank[chunk_at] + 1 + _AHEAD):
                            pending[order[submitted]] = pool.submit(self._load, order[submitted])
                            submitted += 1
                        chunk = loaded[chunk_at] = pending.pop(chunk_at).result()
                        if chunk.problem:
                            raise CorruptChunksError([(self._chunks[chunk_at], chunk.problem)])
                        self._checked.add(chunk_at)
                    message = chunk.message(
                        data, chunk_at, offset, (channel_id, log_time_ns), publish_times_ns
                    )
                    left[chunk_at] -= 1
                    if not left[chunk_at]:
                        del loaded[chunk_at]
                        self._release(chunk_at)
                    if message is not None:
                        yield message
            finally:
                for future in pending.values():
                    future.cancel()

    def _release(self, chunk_at: int) -> None:
        """Give the pages of a chunk whose messages are all read back to the system (the mapped
        file would otherwise count whole in the process's memory by the end of a pass; a page
        read again comes back from the file)."""
        mapping = self._mapping
        if mapping is None or not hasattr(mmap, "MADV_DONTNEED"):
            return
        chunk = self._chunks[chunk_at]
        start = chunk.chunk_start_offset - chunk.chunk_start_offset % mmap.PAGESIZE
        end = min(chunk.chunk_start_offset + chunk.chunk_length, len(mapping))
        if end > start:
            with contextlib.suppress(OSError, ValueError):
                mapping.madvise(mmap.MADV_DONTNEED, start, end - start)

    # ------------------------------------------------------------------ loading chunks
    def _load(self, chunk_at: int) -> _Loaded:
        """Check one chunk and walk its records (a loading thread's job).

        A compressed chunk comes back decompressed. A stored chunk is checked and walked where
        it lies in the mapped file; the caller copies its messages from there. A stored chunk
        checked by an earlier pass is only walked (its record headers).
        """
        chunk = self._chunks[chunk_at]
        check = chunk_at not in self._checked or bool(chunk.compression)
        try:
            records = None
            if chunk.compression:
                records = self._decompressed(chunk)
                heads, whole = _walk(records)
            else:
                heads, whole = self._stored_heads(chunk, check)
            entries = [(offset, head[1], head[3]) for offset, head in heads.items()]
            if check and not (whole and entries == self._entries[chunk_at]):
                raise _Damaged("its message index disagrees with its records")
        except _Damaged as exc:
            return _Loaded(problem=str(exc))
        return _Loaded(heads=heads, records=records)

    def _decompressed(self, chunk: ChunkIndex) -> bytes:
        """The records of a compressed chunk, decompressed, their CRC checked."""
        data = self._data()
        start = chunk.chunk_start_offset
        if start + chunk.chunk_length > len(data):
            raise _Damaged("cut short")
        with data[start : start + chunk.chunk_length] as view:
            return _decompressed(view, chunk.compression)

    def _stored_heads(self, chunk: ChunkIndex, check: bool) -> tuple[dict[int, _Head], bool]:
        """The message heads of a stored chunk, walked where it lies in the mapped file (no
        copy), and whether its records end where it does; ``check``: its CRC first."""
        data = self._data()
        start = chunk.chunk_start_offset
        end = start + chunk.chunk_length
        if end > len(data) or chunk.chunk_length < STORED_CHUNK_HEADER.size:
            raise _Damaged("cut short")
        with data[start:end] as record, record[STORED_CHUNK_HEADER.size :] as records:
            opcode, _, _, _, _, crc, compression, records_length = STORED_CHUNK_HEADER.unpack_from(
                record
            )
            if opcode != Opcode.CHUNK or compression != 0 or records_length != len(records):
                raise _Damaged("its header does not match the summary's chunk index")
            if check and crc and isal_zlib.crc32(records) != crc:
                raise _Damaged("CRC mismatch")
            return _walk(records)

    def _data(self) -> memoryview:
        """The whole file, mapped read-only (its bytes for an in-memory stream)."""
        with self._lock:
            if self._view is None:
                try:
                    fileno = self._stream.fileno()
                except (AttributeError, OSError, ValueError):  # an in-memory stream
                    self._stream.seek(0)
                    self._view = memoryview(self._stream.read())
                    return self._view
                if os.fstat(fileno).st_size == 0:
                    return memoryview(b"")
                self._mapping = mmap.mmap(fileno, 0, access=mmap.ACCESS_READ)
                self._view = memoryview(self._mapping)
            return self._view


@dataclass
class _Loaded:
    """A chunk checked for a pass: why it is damaged ("" if it is not), the head of each
    message record by offset, and the records of a compressed chunk (None for a stored one,
    whose messages' data is read where it lies)."""

    problem: str = ""
    heads: dict[int, _Head] = field(default_factory=dict)
    records: bytes | None = None

    def message(
        self,
        data: memoryview,
        chunk_at: int,
        offset: int,
        indexed: tuple[int, int],
        publish_times_ns: Container[int] | None,
    ) -> MessageFields | None:
        """The message at ``offset``, which its index says is ``indexed`` (channel id, log
        time), copied from the checked records (``data``: the mapped file, for a stored
        chunk); None if its publish time is not wanted."""
        head = self.heads.get(offset)
        if head is None or (head[1], head[3]) != indexed:
            at = chunk_at + STORED_CHUNK_HEADER.size + offset
            raise DamagedLogError(
                f"no message of channel {indexed[0]} at byte {at}, where its index points"
            )
        length, channel, sequence, log_time, publish_time = head
        if publish_times_ns is not None and publish_time not in publish_times_ns:
            return None
        if self.records is not None:
            start = offset + MESSAGE_HEADER.size
            payload = self.records[start : offset + RECORD_HEADER.size + length]
        else:
            at = chunk_at + STORED_CHUNK_HEADER.size + offset
            stop = at + RECORD_HEADER.size + length
            if stop > len(data):
                raise DamagedLogError(f"the message at byte {at} is cut short")
            payload = bytes(data[at + MESSAGE_HEADER.size : stop])
        return channel, sequence, log_time, publish_time, payload


def _decompressed(record: memoryview, compression: str) -> bytes:
    """The records of a compressed chunk record, decompressed, their CRC checked."""
    opcode, length = RECORD_HEADER.unpack_from(record)
    _, _, size, crc = CHUNK_FIELDS.unpack_from(record, RECORD_HEADER.size)
    at = RECORD_HEADER.size + CHUNK_FIELDS.size
    (n,) = _U32.unpack_from(record, at)
    name = bytes(record[at + 4 : at + 4 + n])
    at += 4 + n
    if (
        opcode != Opcode.CHUNK
        or RECORD_HEADER.size + length != len(record)
        or name != compression.encode()
        or at + 8 > len(record)
        or at + 8 + _U64.unpack_from(record, at)[0] != len(record)
    ):
        raise _Damaged("its header does not match the summary's chunk index")
    try:
        with record[at + 8 :] as payload:
            records = decompress(compression, payload, size)
    except DecompressionError as exc:
        raise _Damaged(str(exc)) from None
    if crc and isal_zlib.crc32(records) != crc:
        raise _Damaged("CRC mismatch")
    return records


def _walk(records: bytes | memoryview) -> tuple[dict[int, _Head], bool]:
    """The head of every message record by offset, and whether the records end exactly where
    the chunk does (the walk stops where they do not)."""
    heads: dict[int, _Head] = {}
    pos = 0
    stop = len(records)
    while pos + RECORD_HEADER.size <= stop:
        opcode, length = RECORD_HEADER.unpack_from(records, pos)
        if opcode == Opcode.MESSAGE:
            if pos + MESSAGE_HEADER.size > stop or length < MESSAGE_FIELDS:
                break
            head = MESSAGE_HEADER.unpack_from(records, pos)
            heads[pos] = head[1:]
        elif opcode not in _IN_CHUNK:
            break  # a chunk holds schemas, channels and messages only
        pos += RECORD_HEADER.size + length
    return heads, pos == stop
