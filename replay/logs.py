"""Open a finished bearing-slam log for processing: checks first, then messages in log-time order.

Built on :class:`recorder.logread.LogReader` (which recognises a file that is not MCAP or is
unfinished) and mcap's indexed reader (channels, time ranges, log-time order). Every problem a
user can cause is one line: not MCAP, unfinished (``bslam recover``), no session metadata, no
camera calibration, a channel with a schema this version does not know.
"""

from __future__ import annotations

import json
import os
from collections.abc import Collection, Iterator
from pathlib import Path
from types import TracebackType
from typing import IO

from mcap.exceptions import McapError
from mcap.reader import McapReader, make_reader

from data_schemas.errors import LogError, MissingMetadataError, UnknownSchemaError
from data_schemas.registry import IMAGE_SCHEMAS, SESSION_METADATA_NAME, TOPICS, schema_dict
from data_schemas.session import Session, session_from_metadata
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
        self._schemas = {} if summary is None else summary.schemas
        self._channels = {} if summary is None else summary.channels
        self.topics: dict[str, str] = {}
        for channel in self._channels.values():
            schema = self._schemas.get(channel.schema_id)
            self.topics[channel.topic] = "" if schema is None else schema.name
        self._check_schemas()

    def _check_schemas(self) -> None:
        for topic_name, schema_name in self.topics.items():
            try:
                schema_dict(schema_name)
            except UnknownSchemaError:
                self.close()
                raise UnknownSchemaError(
                    f"{self.name}: channel {topic_name} has schema {schema_name!r}, which this "
                    "version of bearing-slam does not know; upgrade bearing-slam"
                ) from None
            known = TOPICS.get(topic_name)
            allowed = (
                IMAGE_SCHEMAS if topic_name == "/camera/panorama" else (known and known.schema,)
            )
            if known is not None and schema_name not in allowed:
                self.close()
                raise UnknownSchemaError(
                    f"{self.name}: channel {topic_name} has schema {schema_name!r}, expected "
                    f"{' or '.join(str(a) for a in allowed)}"
                )

    def messages(
        self,
        topics: Collection[str] | None = None,
        *,
        start_ns: int | None = None,
        end_ns: int | None = None,
    ) -> Iterator[LogMessage]:
        """Messages of ``topics`` with ``start_ns <= log_time < end_ns``, in log-time order."""
        wanted = None if topics is None else list(topics)
        try:
            for schema, channel, message in self._reader.iter_messages(
                topics=wanted, start_time=start_ns, end_time=end_ns, log_time_order=True
            ):
                yield LogMessage(
                    channel.topic,
                    "" if schema is None else schema.name,
                    message.log_time,
                    message.publish_time,
                    message.sequence,
                    message.data,
                )
        except McapError as exc:
            raise LogError(
                f"{self.name}: the log is damaged ({exc}); try `bslam recover`"
            ) from None

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
