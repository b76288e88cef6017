"""A log still being written, for the runner: the session first, then messages as they arrive.

:class:`FollowedLog` wraps :class:`data_schemas.mcap.follow.LogFollower`: it waits for the
session metadata (the recorder writes it before the first chunk), checks it as
:class:`data_schemas.mcap.processable.ProcessableLog` does, and gives the messages of every
whole chunk in file order, which is log-time order for the recorder's logs. Reading ends when
the log is finished or has not grown for ``idle_timeout_s`` seconds;
:attr:`FollowedLog.end_line` then says which.
"""

from __future__ import annotations

import os
from collections.abc import Collection, Iterator
from pathlib import Path

from data_schemas.closing import Closing
from data_schemas.errors import MissingMetadataError
from data_schemas.mcap.follow import IDLE_TIMEOUT_S, FollowEnd, LogFollower
from data_schemas.mcap.processable import check_calibration, check_channel
from data_schemas.mcap.read import LogMessage
from data_schemas.registry import SESSION_METADATA_NAME
from data_schemas.session import Session, session_from_metadata


class FollowedLog(Closing):
    """A log followed while it grows (see the module docstring).

    Parameters
    ----------
    path : str or os.PathLike
        The ``.mcap`` file; it may not exist yet.
    idle_timeout_s : float
        Stop once the file has not grown for this long (also how long to wait for it to appear).
    poll_s : float
        Period of the file-size checks while waiting, seconds.

    Raises
    ------
    LogError, NotMcapError, MissingMetadataError, SchemaError
        The file did not appear, is not MCAP, or its session is missing or invalid.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        idle_timeout_s: float = IDLE_TIMEOUT_S,
        poll_s: float = 0.05,
    ) -> None:
        self.path = Path(path)
        self.name = self.path.name
        #: foreign channels ignored, one line each
        self.notes: list[str] = []
        self._follower = LogFollower(path, idle_timeout_s=idle_timeout_s, poll_s=poll_s)
        try:
            metadata = self._follower.metadata
            check_calibration(self.name, metadata)
            try:
                self.session: Session = session_from_metadata(metadata[SESSION_METADATA_NAME])
            except MissingMetadataError as exc:
                raise MissingMetadataError(f"{self.name}: {exc}") from None
        except BaseException:
            self._follower.close()
            raise

    @property
    def end(self) -> FollowEnd | None:
        """``"finished"`` (footer written), ``"idle"`` (time-out) or None (still reading)."""
        return self._follower.end

    @property
    def end_line(self) -> str:
        """One line on why reading stopped."""
        return self._follower.end_line

    def messages(self, topics: Collection[str] | None = None) -> Iterator[LogMessage]:
        """Messages of ``topics`` (all if None) as whole chunks arrive, until the log ends.

        Raises
        ------
        UnknownSchemaError
            One of our channels has a schema this version cannot read (checked when it first
            appears); another tool's channel is ignored with a line in :attr:`notes`.
        """
        usable: dict[tuple[str, str], bool] = {}
        for topic, schema, message in self._follower.messages():
            if (topic, schema) not in usable:
                note = check_channel(self.name, topic, schema)
                if note is not None:
                    self.notes.append(note)
                usable[(topic, schema)] = note is None
            if usable[(topic, schema)] and (topics is None or topic in topics):
                yield LogMessage(
                    topic,
                    schema,
                    message.log_time,
                    message.publish_time,
                    message.sequence,
                    message.data,
                )

    def close(self) -> None:
        """Close the file."""
        self._follower.close()
