"""LogReader, for tests: a bearing-slam log in file order, every chunk checked on the way.

Built on :class:`data_schemas.mcap.scan.LogScan`: it reads any valid MCAP (stored or compressed
chunks, unchunked files, metadata anywhere), checks chunk CRCs and message indexes, and refuses
a damaged file with one line. The package's own readers are in ``data_schemas/mcap/open.py``;
this one shares no reading code with :class:`data_schemas.mcap.processable.ProcessableLog`,
so tests check the processable reader and the writer against it.
"""

from __future__ import annotations

import io
import os
from collections.abc import Collection, Iterator
from typing import IO

from mcap.records import Channel, Message, Metadata, Schema

from data_schemas.closing import Closing
from data_schemas.errors import (
    CorruptLogError,
    MissingMetadataError,
    UnfinishedLogError,
    recover_hint,
)
from data_schemas.mcap.read import LogMessage, corrupt_log_line, corruption, unfinished_line
from data_schemas.mcap.scan import LogScan
from data_schemas.registry import SESSION_METADATA_NAME
from data_schemas.session import Session, session_from_metadata

Source = str | os.PathLike[str] | IO[bytes]


class LogReader(Closing):
    """Stream a bearing-slam MCAP log in file order (one checking pass at open).

    Parameters
    ----------
    source : str, os.PathLike or binary stream (seekable)
        The log.
    allow_unfinished : bool
        Read an unfinished log (up to its last complete message) instead of raising
        :class:`UnfinishedLogError`.
    allow_corrupt : bool
        Read a corrupt log (what :class:`LogScan` salvages) instead of raising
        :class:`CorruptLogError`.

    Raises
    ------
    NotMcapError
        The file does not start with the MCAP magic.
    UnfinishedLogError
        The log has no footer and ``allow_unfinished`` is false (says how many messages are
        readable and suggests ``bslam recover``).
    CorruptLogError
        A chunk fails its CRC, an index disagrees with its chunk, or records are unreadable
        (names the first damage, its time range and topics, and suggests ``bslam recover``).
    """

    def __init__(
        self, source: Source, *, allow_unfinished: bool = False, allow_corrupt: bool = False
    ) -> None:
        if isinstance(source, str | os.PathLike):
            self.name = os.fspath(source)
            self._source: str | bytes = self.name
        else:
            self.name = str(getattr(source, "name", "<stream>"))
            source.seek(0)
            self._source = source.read()
        #: complete chunks seen (CRC checked)
        self.chunk_count = 0
        #: bytes after the last complete record (a cut-off end), 0 if none
        self.trailing_bytes = 0
        self.metadata: dict[str, dict[str, str]] = {}
        count = 0
        with self._scan() as scan:
            for record in scan.records():
                if isinstance(record, Metadata):
                    self.metadata.setdefault(record.name, dict(record.metadata))
                elif isinstance(record, Message):
                    count += 1
            self._note(scan)
            #: every damaged stretch found (a cut-off end included)
            self.damage = scan.damage
            self.finished = scan.finished and not scan.damage
        corrupt = corruption(self.damage)
        if corrupt and not allow_corrupt:
            raise CorruptLogError(corrupt_log_line(self.name, corrupt, recover_hint(self.name)))
        if not scan.finished and not allow_unfinished:
            raise UnfinishedLogError(unfinished_line(self.name, count))

    def _scan(self) -> LogScan:
        if isinstance(self._source, bytes):
            return LogScan(io.BytesIO(self._source))
        return LogScan(self._source)

    def _note(self, scan: LogScan) -> None:
        self.chunk_count = scan.chunks
        self.trailing_bytes = scan.trailing_bytes

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
        """Schema, channel and message records that check out, in file order."""
        with self._scan() as scan:
            for record in scan.records():
                if isinstance(record, Schema | Channel | Message):
                    yield record
            self._note(scan)

    def close(self) -> None:
        """Nothing stays open between passes (kept for ``with`` blocks)."""
