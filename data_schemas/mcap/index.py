"""Read chosen channels of a finished log where they lie, through its message indexes.

mcap's indexed reader parses every record of every chunk that holds a wanted channel, through
thousands of small reads, and does it again on each pass. The recorder stores chunks
uncompressed (frames are PNG already) and follows each with one message index per channel
(log time, offset in the chunk), so a message can be read in place from the mapped file: a
31-byte header, its data, and nothing else of the chunk. :class:`LogIndex` does that, in mcap's
log-time order (log time, then position in the file). Before a pass yields anything, every chunk
it reads from is checked once (CRC, and its message indexes against its records): a damaged
chunk raises :class:`CorruptChunksError`. Logs with compressed chunks or without message indexes
(other writers) are left to the checking scan: :meth:`LogIndex.of` returns None for them.
"""

from __future__ import annotations

import mmap
import os
from collections.abc import Collection, Container, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import IO

from isal import isal_zlib
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import ChunkIndex, Message
from mcap.summary import Summary

from data_schemas.mcap.layout import (
    INDEX_ENTRY,
    INDEX_FIELDS,
    MESSAGE_FIELDS,
    MESSAGE_HEADER,
    RECORD_HEADER,
    STORED_CHUNK_HEADER,
)

#: Threads that check chunks (CRC and index) in parallel.
_CHECK_THREADS = 2
#: Where one message lies: log time, file offset of its chunk's records, offset in them, channel
#: id. Tuples sort in mcap's log-time order (log time, then position in the file).
_Place = tuple[int, int, int, int]


class DamagedLogError(McapError):
    """An index entry does not point at a whole message of its channel."""


class CorruptChunksError(DamagedLogError):
    """Chunks a read needs fail their CRC or disagree with their message indexes."""

    def __init__(self, chunks: list[tuple[ChunkIndex, str]]) -> None:
        super().__init__(
            "; ".join(f"chunk at byte {c.chunk_start_offset}: {problem}" for c, problem in chunks)
        )
        self.chunks = chunks


class LogIndex:
    """Where every message of a finished log lies (see :meth:`of`), and reading them there.

    Parameters
    ----------
    stream : binary file (seekable)
        The open log; read, never closed here.
    places : dict channel id -> list of (log time, records offset, offset, channel id)
        Every message's place, from the log's message indexes.
    """

    def __init__(
        self,
        stream: IO[bytes],
        places: dict[int, list[_Place]],
        chunks: Sequence[ChunkIndex] = (),
    ) -> None:
        self._stream = stream
        self._places = places
        self._chunks = {c.chunk_start_offset + STORED_CHUNK_HEADER.size: c for c in chunks}
        self._checked: set[int] = set()  # records offsets of chunks that checked out
        self._mapping: mmap.mmap | None = None
        self._view: memoryview | None = None

    @property
    def channel_ids(self) -> list[int]:
        """Channels with indexed messages."""
        return list(self._places)

    @classmethod
    def of(cls, stream: IO[bytes], summary: Summary | None) -> LogIndex | None:
        """The index of a log whose chunks are stored and all indexed, else None.

        Reads the message indexes after each chunk (small records) and nothing else. None when
        a chunk is compressed, when chunks or message indexes are missing, or when the indexes
        do not count every message of the summary's statistics.
        """
        if summary is None or not summary.chunk_indexes:
            return None
        if any(c.compression or not c.message_index_length for c in summary.chunk_indexes):
            return None
        places: dict[int, list[_Place]] = {}
        for chunk in summary.chunk_indexes:
            records_at = chunk.chunk_start_offset + STORED_CHUNK_HEADER.size
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
                        (log_time_ns, records_at, offset, channel_id)
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

        ``chunks``: records offsets of the chunks to check (default all); each chunk is checked
        once (its bytes are mapped, not copied; the CRC needs them all).
        """
        todo = [r for r in (self._chunks if chunks is None else chunks) if r not in self._checked]
        if not todo:
            return []
        wanted = set(todo)
        by_chunk: dict[int, list[tuple[int, int, int]]] = {r: [] for r in todo}
        for places in self._places.values():
            for log_time_ns, records_at, offset, channel_id in places:
                if records_at in wanted:
                    by_chunk[records_at].append((offset, channel_id, log_time_ns))
        data = self._data()

        def check(records_at: int) -> str:
            """Why the chunk is damaged ("" if it is not)."""
            chunk = self._chunks[records_at]
            start = chunk.chunk_start_offset
            stop = start + chunk.chunk_length
            if stop > len(data):
                return "cut short"
            with data[start:stop] as record:
                if not _chunk_whole(record):
                    return "CRC mismatch"
                found = _messages_in(record[STORED_CHUNK_HEADER.size :])
                if found != sorted(by_chunk[records_at]):
                    return "its message index disagrees with its records"
            return ""

        # the CRC (ISA-L) releases the GIL: a second core checks chunks alongside
        with ThreadPoolExecutor(max_workers=_CHECK_THREADS) as pool:
            results = list(pool.map(check, todo))
        bad = []
        for records_at, problem in zip(todo, results, strict=True):
            if problem:
                bad.append((self._chunks[records_at], problem))
            else:
                self._checked.add(records_at)
        return bad

    def channels_in(self, chunk: ChunkIndex) -> set[int]:
        """Channel ids with messages in ``chunk``."""
        records_at = chunk.chunk_start_offset + STORED_CHUNK_HEADER.size
        return {c for c, places in self._places.items() if any(p[1] == records_at for p in places)}

    def close(self) -> None:
        """Release the file's mapping (the stream stays open: it is the caller's)."""
        if self._view is not None:
            self._view.release()
            self._view = None
        if self._mapping is not None:
            self._mapping.close()
            self._mapping = None

    def _data(self) -> memoryview:
        """The whole file, mapped read-only (empty view for an empty file)."""
        if self._view is None:
            try:
                fileno = self._stream.fileno()
            except (AttributeError, OSError, ValueError):  # an in-memory stream: its bytes
                self._stream.seek(0)
                self._view = memoryview(self._stream.read())
                return self._view
            if os.fstat(fileno).st_size == 0:
                return memoryview(b"")
            # populated at once: one pass of the kernel, not a page fault per 4 KiB read
            flags = mmap.MAP_SHARED | getattr(mmap, "MAP_POPULATE", 0)
            self._mapping = mmap.mmap(self._stream.fileno(), 0, flags=flags, prot=mmap.PROT_READ)
            self._view = memoryview(self._mapping)
        return self._view

    def messages(
        self,
        channel_ids: Collection[int],
        *,
        start_ns: int | None = None,
        end_ns: int | None = None,
        publish_times_ns: Container[int] | None = None,
    ) -> Iterator[Message]:
        """Messages of ``channel_ids`` with ``start_ns <= log_time < end_ns``, in log-time order.

        ``publish_times_ns``, if given, keeps only messages whose publish time is in it; the
        others' data is not read.

        Raises
        ------
        DamagedLogError
            An index entry points outside the file or at something else than its message.
        """
        wanted = sorted(
            p
            for c in channel_ids
            for p in self._places.get(c, ())
            if (start_ns is None or p[0] >= start_ns) and (end_ns is None or p[0] < end_ns)
        )
        bad = self.verify({p[1] for p in wanted})  # the chunks this pass reads, before any
        if bad:
            raise CorruptChunksError(bad)
        data = self._data()
        for place in wanted:
            message = self._read(data, place, publish_times_ns)
            if message is not None:
                yield message

    def _read(
        self, data: memoryview, place: _Place, publish_times_ns: Container[int] | None
    ) -> Message | None:
        log_time_ns, records_at, offset, channel_id = place
        at = records_at + offset
        if at + MESSAGE_HEADER.size > len(data):
            raise DamagedLogError(f"a message index points past the end of the file (byte {at})")
        opcode, length, channel, sequence, log_time, publish_time = MESSAGE_HEADER.unpack_from(
            data, at
        )
        if (
            opcode != Opcode.MESSAGE
            or (channel, log_time) != (channel_id, log_time_ns)
            or length < MESSAGE_FIELDS
        ):
            raise DamagedLogError(
                f"no message of channel {channel_id} at byte {at}, where its index points"
            )
        if publish_times_ns is not None and publish_time not in publish_times_ns:
            return None
        end = at + RECORD_HEADER.size + length
        if end > len(data):
            raise DamagedLogError(f"the message at byte {at} is cut short")
        return Message(
            channel_id=channel,
            log_time=log_time,
            data=bytes(data[at + MESSAGE_HEADER.size : end]),
            publish_time=publish_time,
            sequence=sequence,
        )


def _chunk_whole(record: memoryview) -> bool:
    """A stored chunk record whose CRC (if set) matches its records."""
    fields = STORED_CHUNK_HEADER.unpack_from(record)
    crc: int = fields[5]
    records_length: int = fields[7]
    if fields[0] != Opcode.CHUNK or fields[6] != 0:
        return False
    if records_length != len(record) - STORED_CHUNK_HEADER.size:
        return False
    return crc == 0 or isal_zlib.crc32(record[STORED_CHUNK_HEADER.size :]) == crc


def _messages_in(records: memoryview) -> list[tuple[int, int, int]]:
    """(offset, channel id, log time) of every message record, sorted; [] if malformed."""
    found = []
    pos = 0
    end = len(records)
    while pos < end:
        if pos + RECORD_HEADER.size > end:
            return [(-1, -1, -1)]
        opcode, length = RECORD_HEADER.unpack_from(records, pos)
        if opcode == Opcode.MESSAGE:
            if pos + MESSAGE_HEADER.size > end:
                return [(-1, -1, -1)]
            _, _, channel, _, log_time, _ = MESSAGE_HEADER.unpack_from(records, pos)
            found.append((pos, channel, log_time))
        pos += RECORD_HEADER.size + length
    return found if pos == end else [(-1, -1, -1)]
