"""Open a finished bearing-slam log for processing: checks first, then messages in log-time order.

Built on :class:`recorder.logread.LogReader` (which recognises a file that is not MCAP or is
unfinished) and the log's indexes (channels, time ranges, log-time order): messages are read in
place through :class:`recorder.logindex.LogIndex` when the chunks are stored (the recorder's
logs), by mcap's reader otherwise. Every problem a user can cause is one line: not MCAP,
unfinished (``bslam recover``), no session metadata, no camera calibration, a channel with a
schema this version does not know, a damaged log.
"""

from __future__ import annotations

import json
import os
from collections.abc import Collection, Container, Iterator
from pathlib import Path
from types import TracebackType
from typing import IO

from mcap.exceptions import McapError
from mcap.reader import McapReader, make_reader
from mcap.records import Message

from data_schemas.errors import LogError, MissingMetadataError, UnknownSchemaError
from data_schemas.registry import IMAGE_SCHEMAS, SESSION_METADATA_NAME, TOPICS, schema_dict
from data_schemas.session import Session, session_from_metadata
from recorder.logindex import LogIndex
from recorder.logread import LogMessage, LogReader


def _check_calibration(name: str, metadata: dict[str, dict[str, str]]) -> None:
    record = metadata.get(SESSION_METADATA_NAME)
    if record is None:
        raise MissingMetadataError(
            f"{name} has no {SESSION_METADATA_NAME!r} session metadata "
            "(not a bearing-slam recording?)"
        )
    try:
        doc = json.loads(record.get("json", "null"))
    except json.JSONDecodeError:
        return  # session_from_metadata names this problem
    camera = doc.get("camera") if isinstance(doc, dict) else None
    if not isinstance(camera, dict) or "calibration" not in camera:
        raise MissingMetadataError(
            f"{name}: the session metadata has no camera calibration, so frames cannot be "
            "turned into bearings; record with a calibrated camera"
        )


def check_channel(name: str, topic_name: str, schema_name: str) -> None:
    """Raise UnknownSchemaError if this version cannot read ``topic_name`` with that schema."""
    try:
        schema_dict(schema_name)
    except UnknownSchemaError:
        raise UnknownSchemaError(
            f"{name}: channel {topic_name} has schema {schema_name!r}, which this "
            "version of bearing-slam does not know; upgrade bearing-slam"
        ) from None
    known = TOPICS.get(topic_name)
    allowed = IMAGE_SCHEMAS if topic_name == "/camera/panorama" else (known and known.schema,)
    if known is not None and schema_name not in allowed:
        raise UnknownSchemaError(
            f"{name}: channel {topic_name} has schema {schema_name!r}, expected "
            f"{' or '.join(str(a) for a in allowed)}"
        )


class ProcessableLog:
    """A finished log with valid session metadata and only known schemas.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.mcap`` file.

    Raises
    ------
    NotMcapError, UnfinishedLogError, MissingMetadataError, SchemaError, UnknownSchemaError
        One line naming the file and what to do.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self.name = self.path.name
        with LogReader(self.path) as reader:
            metadata = reader.metadata
        _check_calibration(self.name, metadata)
        try:
            self.session: Session = session_from_metadata(metadata[SESSION_METADATA_NAME])
        except MissingMetadataError as exc:
            raise MissingMetadataError(f"{self.name}: {exc}") from None
        self._file: IO[bytes] = open(self.path, "rb")  # noqa: SIM115 (closed in close)
        try:
            self._reader: McapReader = make_reader(self._file)
            summary = self._reader.get_summary()
        except McapError as exc:
            self._file.close()
            raise LogError(f"{self.name}: cannot read the log's index ({exc})") from None
        self._index = LogIndex.of(self._file, summary)
        schemas = {} if summary is None else summary.schemas
        #: channel id -> (topic, schema name)
        self._channel_names: dict[int, tuple[str, str]] = {}
        self.topics: dict[str, str] = {}
        for channel_id, channel in ({} if summary is None else summary.channels).items():
            schema = schemas.get(channel.schema_id)
            schema_name = "" if schema is None else schema.name
            self.topics[channel.topic] = schema_name
            self._channel_names[channel_id] = (channel.topic, schema_name)
        self._check_schemas()

    def _check_schemas(self) -> None:
        for topic_name, schema_name in self.topics.items():
            try:
                check_channel(self.name, topic_name, schema_name)
            except UnknownSchemaError:
                self.close()
                raise

    def messages(
        self,
        topics: Collection[str] | None = None,
        *,
        start_ns: int | None = None,
        end_ns: int | None = None,
        publish_times_ns: Container[int] | None = None,
    ) -> Iterator[LogMessage]:
        """Messages of ``topics`` with ``start_ns <= log_time < end_ns``, in log-time order.

        ``publish_times_ns``, if given, keeps only messages whose publish time is in it (in a
        log the recorder wrote, the others' data is not even read).
        """
        wanted = None if topics is None else list(topics)
        try:
            for topic_name, schema_name, message in self._found(
                wanted, start_ns, end_ns, publish_times_ns
            ):
                yield LogMessage(
                    topic_name,
                    schema_name,
                    message.log_time,
                    message.publish_time,
                    message.sequence,
                    message.data,
                )
        except McapError as exc:
            raise LogError(
                f"{self.name}: the log is damaged ({exc}); try `bslam recover`"
            ) from None

    def _found(
        self,
        topics: list[str] | None,
        start_ns: int | None,
        end_ns: int | None,
        publish_times_ns: Container[int] | None,
    ) -> Iterator[tuple[str, str, Message]]:
        """(topic, schema name, message): read in place if the log allows, else by mcap."""
        if self._index is not None:
            names = self._channel_names
            ids = [i for i, (t, _) in names.items() if topics is None or t in topics]
            for message in self._index.messages(
                ids, start_ns=start_ns, end_ns=end_ns, publish_times_ns=publish_times_ns
            ):
                yield (*names[message.channel_id], message)
            return
        for schema, channel, message in self._reader.iter_messages(
            topics=topics, starting_at=start_ns, ending_before=end_ns, log_time_order=True
        ):
            if publish_times_ns is None or message.publish_time in publish_times_ns:
                yield channel.topic, "" if schema is None else schema.name, message

    def close(self) -> None:
        """Close the file."""
        self._file.close()

    def __enter__(self) -> ProcessableLog:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
