"""Read chosen channels of a finished log where they lie, through its message indexes.

mcap's indexed reader parses every record of every chunk that holds a wanted channel, through
thousands of small reads, and does it again on each pass. The recorder stores chunks
uncompressed (frames are PNG already) and follows each with one message index per channel
(log time, offset in the chunk), so a message can be read in place: one seek, a 31-byte header,
its data, and nothing else of the chunk. :class:`LogIndex` does that, in mcap's log-time order
(log time, then position in the file). Logs with compressed chunks or without message indexes
(other writers) are left to mcap's reader: :meth:`LogIndex.of` returns None for them.
"""

from __future__ import annotations

import struct
from collections.abc import Collection, Container, Iterator
from typing import IO

from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Message
from mcap.summary import Summary

from data_schemas.mcap.chunks import (
    MESSAGE_FIELDS,
    MESSAGE_HEADER,
    RECORD_HEADER,
    STORED_CHUNK_HEADER,
)

#: Message index body up to its entries: channel id, entries length in bytes.
_INDEX_FIELDS = struct.Struct("<HI")
#: One index entry: log time, offset of the message record in the chunk's records.
_ENTRY = struct.Struct("<QQ")
#: Where one message lies: log time, file offset of its chunk's records, offset in them, channel
#: id. Tuples sort in mcap's log-time order (log time, then position in the file).
_Place = tuple[int, int, int, int]


class DamagedLogError(McapError):
    """An index entry does not point at a whole message of its channel."""


class LogIndex:
    """Where every message of a finished log lies (see :meth:`of`), and reading them there.

    Parameters
    ----------
    stream : binary file (seekable)
        The open log; read, never closed here.
    places : dict channel id -> list of (log time, records offset, offset, channel id)
        Every message's place, from the log's message indexes.
    """

    def __init__(self, stream: IO[bytes], places: dict[int, list[_Place]]) -> None:
        self._stream = stream
        self._places = places

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
            while pos + RECORD_HEADER.size + _INDEX_FIELDS.size <= len(block):
                opcode, length = RECORD_HEADER.unpack_from(block, pos)
                body = pos + RECORD_HEADER.size
                if opcode == Opcode.MESSAGE_INDEX:
                    channel_id, size = _INDEX_FIELDS.unpack_from(block, body)
                    first = body + _INDEX_FIELDS.size
                    places.setdefault(channel_id, []).extend(
                        (log_time_ns, records_at, offset, channel_id)
                        for log_time_ns, offset in _ENTRY.iter_unpack(block[first : first + size])
                    )
                pos = body + length
        counted = sum(len(p) for p in places.values())
        if summary.statistics is None or counted != summary.statistics.message_count:
            return None
        return cls(stream, places)

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
        for place in wanted:
            message = self._read(place, publish_times_ns)
            if message is not None:
                yield message

    def _read(self, place: _Place, publish_times_ns: Container[int] | None) -> Message | None:
        log_time_ns, records_at, offset, channel_id = place
        at = records_at + offset
        self._stream.seek(at)
        head = self._stream.read(MESSAGE_HEADER.size)
        if len(head) < MESSAGE_HEADER.size:
            raise DamagedLogError(f"a message index points past the end of the file (byte {at})")
        opcode, length, channel, sequence, log_time, publish_time = MESSAGE_HEADER.unpack(head)
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
        data = self._stream.read(length - MESSAGE_FIELDS)
        if len(data) != length - MESSAGE_FIELDS:
            raise DamagedLogError(f"the message at byte {at} is cut short")
        return Message(
            channel_id=channel,
            log_time=log_time,
            data=data,
            publish_time=publish_time,
            sequence=sequence,
        )
