"""One way in to reading a log: :func:`open_log`, and what every reader gives (:class:`MessageLog`).

A finished log opens as :class:`data_schemas.mcap.processable.ProcessableLog`, a log still being
written (``follow=True``) as :class:`data_schemas.mcap.follow.FollowedLog`; both are a
:class:`MessageLog`. Functions that take "a path, or a log already open" resolve it with
:func:`log_path` and :func:`entered`, nowhere else.
"""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Collection, Iterator
from pathlib import Path
from typing import Literal, Protocol, overload

from data_schemas.mcap.follow import FollowedLog
from data_schemas.mcap.processable import ProcessableLog
from data_schemas.mcap.read import IDLE_TIMEOUT_S, LogMessage
from data_schemas.session import Session

_LOG = logging.getLogger("bslam.logs")


class MessageLog(Protocol):
    """What the runner reads: a log's name, its session, its messages in log-time order.

    :class:`ProcessableLog` (a finished log), :class:`FollowedLog` (a log still being written)
    and :class:`data_schemas.mcap.window.WindowedLog` (a part of a finished one) are each one.
    """

    name: str
    path: Path
    session: Session

    def messages(self, topics: Collection[str] | None = None) -> Iterator[LogMessage]: ...


#: A log to read: its path, or a log already opened (or followed).
LogSource = str | os.PathLike[str] | MessageLog


@overload
def open_log(
    path: str | os.PathLike[str],
    *,
    follow: Literal[False] = False,
    skip_corrupt: bool = False,
    idle_timeout_s: float = IDLE_TIMEOUT_S,
    warn: bool = True,
) -> ProcessableLog: ...


@overload
def open_log(
    path: str | os.PathLike[str],
    *,
    follow: Literal[True],
    skip_corrupt: bool = False,
    idle_timeout_s: float = IDLE_TIMEOUT_S,
    warn: bool = True,
) -> FollowedLog: ...


def open_log(
    path: str | os.PathLike[str],
    *,
    follow: bool = False,
    skip_corrupt: bool = False,
    idle_timeout_s: float = IDLE_TIMEOUT_S,
    warn: bool = True,
) -> ProcessableLog | FollowedLog:
    """Open a log to read: finished, or (``follow``) still being written.

    A finished log's ignored channels and skipped chunks (``skip_corrupt``) are warned about on
    the ``bslam.logs`` logger, unless ``warn`` is False (a look at a log that the run itself
    opens again, such as counting its movements for a progress bar). ``idle_timeout_s``
    (seconds) applies to a followed log only.

    Raises
    ------
    BslamError
        The log is missing, not MCAP, unfinished (when not followed), corrupt (without
        ``skip_corrupt``), or its session is missing or invalid: one line each.
    """
    if follow:
        return FollowedLog(path, idle_timeout_s=idle_timeout_s)
    opened = ProcessableLog(path, skip_corrupt=skip_corrupt)
    if not warn:
        return opened
    for note in opened.notes:
        _LOG.warning(note)
    for damage in opened.skipped:
        _LOG.warning(f"{opened.name}: skipped {damage.describe(salvaged=False)}")
    return opened


def log_path(log: LogSource) -> Path:
    """The file of ``log`` (a path, or a log already open)."""
    return Path(log) if isinstance(log, str | os.PathLike) else log.path


def entered(
    log: LogSource, stack: contextlib.ExitStack[bool | None], *, skip_corrupt: bool = False
) -> MessageLog:
    """``log`` itself if already open; a path opened with :func:`open_log`, closed by ``stack``."""
    if isinstance(log, str | os.PathLike):
        return stack.enter_context(open_log(log, skip_corrupt=skip_corrupt))
    return log
