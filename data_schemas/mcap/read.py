"""Read bearing-slam logs in file order, finished or not, checking every chunk on the way.

:class:`LogReader` is built on :class:`data_schemas.mcap.scan.LogScan`: it reads any valid MCAP
(stored or compressed chunks, unchunked files, metadata anywhere), checks chunk CRCs and message
indexes, and refuses a damaged file with one line (``bslam recover`` rewrites what is left).
An unfinished log (the recorder was killed, or the disk filled up) is readable up to its last
complete message with ``allow_unfinished``.
"""

from __future__ import annotations

import io
import os
from collections.abc import Collection, Iterator
from dataclasses import dataclass, field
from typing import IO, Any

from mcap.records import Channel, Message, Metadata, Schema

from data_schemas.closing import Closing
from data_schemas.codec import decode
from data_schemas.errors import (
    CorruptLogError,
    MissingMetadataError,
    UnfinishedLogError,
    recover_hint,
)
from data_schemas.mcap.scan import Damage, LogScan
from data_schemas.registry import SESSION_METADATA_NAME
from data_schemas.session import Session, session_from_metadata
from data_schemas.shape import check_shape

Source = str | os.PathLike[str] | IO[bytes]

#: Damage that an interrupted recording leaves (the file just ends): "unfinished", not corrupt.
CUT_END = frozenset({"cut chunk", "file end"})


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


def corruption(damage: list[Damage]) -> list[Damage]:
    """The damage that is more than a cut-off end (what makes a log corrupt, not unfinished)."""
    return [d for d in damage if d.what not in CUT_END]


def corrupt_log_line(name: str, damage: list[Damage], advice: str) -> str:
    """One line naming the first damage of a corrupt log, how much more, and what to do."""
    more = f" (and {len(damage) - 1} more)" if len(damage) > 1 else ""
    return f"{name} is corrupt: {damage[0].describe()}{more}; {advice}"


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
            raise UnfinishedLogError(
                f"{self.name} is unfinished (the recording was interrupted): {count} "
                f"messages are readable; {recover_hint(self.name)}"
            )

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
