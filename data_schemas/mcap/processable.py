"""Open a finished bearing-slam log for processing: checks first, then messages in log-time order.

No message is used before its chunk is checked: its CRC, and its message indexes against its
records. A log whose chunks all have message indexes (what the recorder and mcap's ``Writer``
write, stored or compressed) is read through :class:`data_schemas.mcap.index.LogIndex`: each
pass loads the chunks it needs once, a second core reading, decompressing and checking the next
chunks while the caller uses the messages of the one before, and a damaged chunk stops the pass
before any of its messages is handed out. Anything else (unchunked files, no summary or an
incomplete one, damage with ``skip_corrupt``) is checked whole at open by
:class:`data_schemas.mcap.scan.LogScan` and read through it. Every
problem a user can cause is one line: not MCAP, unfinished or corrupt (``bslam recover``, or
``--skip-corrupt`` to process the rest), no session metadata, a camera without calibration, a known
channel with the wrong schema. Channels this version does not know (another tool's ``/chatter``
beside ours) are ignored, with a note in :attr:`ProcessableLog.notes`.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Collection, Container, Iterator
from pathlib import Path
from typing import IO

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.summary import Summary

from data_schemas.closing import Closing
from data_schemas.codec import loads
from data_schemas.errors import (
    CorruptLogError,
    LogError,
    MissingMetadataError,
    SchemaError,
    UnfinishedLogError,
    UnknownSchemaError,
    recover_hint,
)
from data_schemas.inputs import open_input
from data_schemas.mcap.index import CorruptChunksError, DamagedLogError, LogIndex, MessageFields
from data_schemas.mcap.read import LogMessage, corrupt_log_line, corruption, unfinished_line
from data_schemas.mcap.scan import Damage, LogScan
from data_schemas.registry import (
    CAMERA_TOPIC,
    IMAGE_SCHEMAS,
    SESSION_METADATA_NAME,
    TOPICS,
    schema_dict,
)
from data_schemas.session import Session, session_from_metadata


def check_calibration(name: str, metadata: dict[str, dict[str, str]]) -> None:
    """Raise MissingMetadataError unless ``metadata`` holds a session whose camera, if it has one,
    is calibrated (a session without a camera takes its bearings from ``/sensor/bearings``)."""
    record = metadata.get(SESSION_METADATA_NAME)
    if record is None:
        raise MissingMetadataError(
            f"{name} has no {SESSION_METADATA_NAME!r} session metadata "
            "(not a bearing-slam recording?)"
        )
    try:
        doc = loads(record.get("json", "null"), what="session metadata")
    except SchemaError:
        return  # session_from_metadata names this problem
    if isinstance(doc, dict) and "camera" not in doc:
        return
    camera = doc.get("camera") if isinstance(doc, dict) else None
    if not isinstance(camera, dict) or "calibration" not in camera:
        raise MissingMetadataError(
            f"{name}: the session metadata has no camera calibration, so frames cannot be "
            "turned into bearings; record with a calibrated camera"
        )


def check_channel(name: str, topic_name: str, schema_name: str) -> str | None:
    """Check one channel of log ``name``: None if it is used, a note if it is foreign.

    A channel on one of our topics must carry that topic's schema; a channel whose schema this
    version does not know on a topic that is not ours is another tool's and is ignored.

    Raises
    ------
    UnknownSchemaError
        One of our topics with an unknown or wrong schema.
    """
    known = TOPICS.get(topic_name)
    try:
        schema_dict(schema_name)
    except UnknownSchemaError:
        if known is None:
            return (
                f"{name}: channel {topic_name} (schema {schema_name!r}) is not bearing-slam's: "
                "ignored"
            )
        raise UnknownSchemaError(
            f"{name}: channel {topic_name} has schema {schema_name!r}, which this "
            "version of bearing-slam does not know; upgrade bearing-slam"
        ) from None
    allowed = IMAGE_SCHEMAS if topic_name == CAMERA_TOPIC else (known and known.schema,)
    if known is not None and schema_name not in allowed:
        raise UnknownSchemaError(
            f"{name}: channel {topic_name} has schema {schema_name!r}, expected "
            f"{' or '.join(str(a) for a in allowed)}"
        )
    return None


def read_summary(file: IO[bytes]) -> Summary | None:
    """The summary section, if the file has a readable one (else None: scan the file)."""
    try:
        file.seek(0)
        return make_reader(file).get_summary()
    except (McapError, ValueError, KeyError, UnicodeDecodeError, EOFError, struct.error, OSError):
        return None  # too short for the magic (struct), or for the footer (a seek before 0)


def indexed_metadata(file: IO[bytes], summary: Summary) -> dict[str, dict[str, str]]:
    """The metadata records the summary's metadata indexes point to, name -> key/value map
    (the first record of each name; the summary is not read again).

    Raises
    ------
    McapError, ValueError, KeyError, UnicodeDecodeError, EOFError
        An index does not point at a readable metadata record.
    """
    found: dict[str, dict[str, str]] = {}
    for metadata_index in summary.metadata_indexes:
        file.seek(metadata_index.offset)
        record = next(StreamReader(file, skip_magic=True).records, None)
        if not isinstance(record, Metadata):
            raise McapError(f"no metadata record at byte {metadata_index.offset}")
        found.setdefault(record.name, dict(record.metadata))
    return found


class ProcessableLog(Closing):
    """A finished, undamaged log with valid session metadata (see module docstring).

    Parameters
    ----------
    path : str or os.PathLike
        The ``.mcap`` file.
    skip_corrupt : bool
        Process a corrupt log without its damaged chunks (listed in :attr:`skipped`) instead
        of raising :class:`CorruptLogError`.

    Attributes
    ----------
    topics : dict
        Topic -> schema name of the channels used (ignored foreign channels excluded).
    notes : list of str
        Foreign channels ignored, one line each.
    skipped : list of Damage
        Damaged parts left out (``skip_corrupt`` only).

    Raises
    ------
    NotMcapError, UnfinishedLogError, CorruptLogError, MissingMetadataError, SchemaError,
    UnknownSchemaError
        One line naming the file and what to do.
    """

    def __init__(self, path: str | os.PathLike[str], *, skip_corrupt: bool = False) -> None:
        self.path = Path(path)
        self.name = self.path.name
        self.notes: list[str] = []
        self.skipped: list[Damage] = []
        self._skip = skip_corrupt
        self._file: IO[bytes] = open_input(self.path, what="log", error=LogError)
        self._index: LogIndex | None = None
        try:
            self._open(skip_corrupt)
        except BaseException:
            self.close()
            raise

    @property
    def skip_corrupt(self) -> bool:
        """Opened with ``skip_corrupt``: damaged parts (and messages that do not decode) are
        skipped with a warning instead of stopping the run."""
        return self._skip

    def _open(self, skip_corrupt: bool) -> None:
        summary = read_summary(self._file)
        self._index = self._checked_index(summary)
        schemas: dict[int, Schema]
        channels: dict[int, Channel]
        if self._index is not None:
            assert summary is not None
            schemas, channels = summary.schemas, summary.channels
            metadata = self._indexed_metadata(summary)
        else:
            schemas, channels, metadata = self._scanned(skip_corrupt)
        check_calibration(self.name, metadata)
        try:
            self.session: Session = session_from_metadata(metadata[SESSION_METADATA_NAME])
        except MissingMetadataError as exc:
            raise MissingMetadataError(f"{self.name}: {exc}") from None
        #: channel id -> (topic, schema name)
        self._channel_names: dict[int, tuple[str, str]] = {}
        self.topics: dict[str, str] = {}
        for channel_id, channel in channels.items():
            schema = schemas.get(channel.schema_id)
            schema_name = "" if schema is None else schema.name
            if self._usable(channel.topic, schema_name):
                self.topics[channel.topic] = schema_name
                self._channel_names[channel_id] = (channel.topic, schema_name)

    def _checked_index(self, summary: Summary | None) -> LogIndex | None:
        """The index of a log whose chunks are all indexed (None: read it by a scan).

        The index checks each chunk a pass reads before it yields any of its messages. With
        ``skip_corrupt`` every chunk is checked now instead, and a damaged log is left to the
        scan, which skips its damaged parts. A summary without channels or without metadata
        indexes (metadata could lie anywhere) is left to the scan too.
        """
        if summary is None or not summary.channels or not summary.metadata_indexes:
            return None
        index = LogIndex.of(self._file, summary)
        if index is None or any(c not in summary.channels for c in index.channel_ids):
            return None
        if self._skip and index.verify():
            index.close()
            return None
        return index

    def _indexed_metadata(self, summary: Summary) -> dict[str, dict[str, str]]:
        """The metadata records the summary's metadata indexes point to (the summary is not
        read again)."""
        try:
            return indexed_metadata(self._file, summary)
        except (McapError, ValueError, KeyError, UnicodeDecodeError, EOFError) as exc:
            raise LogError(f"{self.name}: cannot read the log's metadata ({exc})") from None

    def _scanned(
        self, skip_corrupt: bool
    ) -> tuple[dict[int, Schema], dict[int, Channel], dict[str, dict[str, str]]]:
        """Check the whole file with a scan: refuse it or note what ``skip_corrupt`` skips."""
        metadata: dict[str, dict[str, str]] = {}
        count = 0
        with LogScan(self.path, salvage=not skip_corrupt) as scan:
            for record in scan.records():
                if isinstance(record, Metadata):
                    metadata.setdefault(record.name, dict(record.metadata))
                elif isinstance(record, Message):
                    count += 1
        corrupt = corruption(scan.damage)
        if corrupt and not skip_corrupt:
            raise CorruptLogError(
                corrupt_log_line(
                    self.name,
                    corrupt,
                    self._advice,
                )
            )
        if not scan.finished and not corrupt:
            raise UnfinishedLogError(unfinished_line(self.name, count, path=os.fspath(self.path)))
        self.skipped = [d for d in corrupt if d.loses_data]
        return scan.schemas, scan.channels, metadata

    def _usable(self, topic_name: str, schema_name: str) -> bool:
        """Whether a channel is used (see :func:`check_channel`); a foreign one is noted."""
        note = check_channel(self.name, topic_name, schema_name)
        if note is not None:
            self.notes.append(note)
        return note is None

    def messages(
        self,
        topics: Collection[str] | None = None,
        *,
        start_ns: int | None = None,
        end_ns: int | None = None,
        publish_times_ns: Container[int] | None = None,
    ) -> Iterator[LogMessage]:
        """Messages of ``topics`` with ``start_ns <= log_time < end_ns``, in log-time order.

        ``publish_times_ns``, if given, keeps only messages whose publish time is in it (in
        stored chunks an earlier pass checked, the others' data is not even read).

        Raises
        ------
        CorruptLogError
            A chunk this pass reads is damaged (raised before any of its messages is yielded;
            a log checked whole at open raises at open instead).
        """
        names = self._channel_names
        ids = [i for i, (t, _) in names.items() if topics is None or t in topics]
        try:
            for channel, sequence, log_time_ns, publish_time_ns, data in self._found(
                ids, start_ns, end_ns, publish_times_ns
            ):
                topic_name, schema_name = names[channel]
                yield LogMessage(
                    topic_name, schema_name, log_time_ns, publish_time_ns, sequence, data
                )
        except CorruptChunksError as exc:
            assert self._index is not None
            damage = [
                Damage(
                    c.chunk_start_offset,
                    c.chunk_start_offset + c.chunk_length,
                    "chunk",
                    problem,
                    c.message_start_time,
                    c.message_end_time,
                    {names[i][0] for i in self._index.channels_in(c) if i in names},
                )
                for c, problem in exc.chunks
            ]
            # what info and recover say of the same damage (salvage counted by one scan)
            damage = _scanned_damage(self.path) or damage
            raise CorruptLogError(corrupt_log_line(self.name, damage, self._advice)) from None
        except DamagedLogError as exc:
            raise CorruptLogError(
                f"{self.name}: the log is damaged ({exc}); {self._advice}"
            ) from None

    def _found(
        self,
        ids: list[int],
        start_ns: int | None,
        end_ns: int | None,
        publish_times_ns: Container[int] | None,
    ) -> Iterator[MessageFields]:
        """The fields of the messages, through the log's index if it has one, else by a scan
        sorted by log time."""
        if self._index is not None:
            yield from self._index.fields(
                ids, start_ns=start_ns, end_ns=end_ns, publish_times_ns=publish_times_ns
            )
            return
        wanted = set(ids)
        found: list[tuple[int, int, Message]] = []
        with LogScan(self.path, salvage=not self._skip) as scan:
            for record in scan.records():
                if (
                    isinstance(record, Message)
                    and record.channel_id in wanted
                    and (start_ns is None or record.log_time >= start_ns)
                    and (end_ns is None or record.log_time < end_ns)
                    and (publish_times_ns is None or record.publish_time in publish_times_ns)
                ):
                    found.append((record.log_time, len(found), record))
        found.sort(key=lambda item: item[:2])
        for _, _, m in found:
            yield m.channel_id, m.sequence, m.log_time, m.publish_time, m.data

    @property
    def _advice(self) -> str:
        return f"{recover_hint(self.path)}, or pass --skip-corrupt to process the rest"

    def close(self) -> None:
        """Close the file."""
        if self._index is not None:
            self._index.close()
        self._file.close()


def _scanned_damage(path: Path) -> list[Damage]:
    """The corruption a full scan of ``path`` finds, with its salvage counts (the numbers
    ``bslam info`` and ``bslam recover`` give); read only once the index found damage."""
    with LogScan(path) as scan:
        for _ in scan.records():
            pass
        return corruption(scan.damage)
