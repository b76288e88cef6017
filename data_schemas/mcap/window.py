"""A part of a log chosen by time or by movement (``--from`` / ``--to``).

A bound is written ``12.5s`` (seconds of log time after the log's first message) or ``m3``
(movement 3: from its start keyframe, or to its end keyframe, both included). ``--from m2 --to
m4`` keeps movements 2, 3 and 4 whole; ``--from 10s --to 60s`` keeps what was logged in that
span; the two kinds mix. :class:`LogWindow` turns the bounds into a log-time range for one log
and :class:`WindowedLog` reads only that range.
"""

from __future__ import annotations

import math
import re
from collections.abc import Collection, Iterator
from dataclasses import dataclass
from pathlib import Path

from data_schemas.errors import BslamError
from data_schemas.mcap.processable import ProcessableLog
from data_schemas.mcap.read import LogMessage
from data_schemas.registry import CAMERA_TOPIC, MOVEMENT_TOPIC
from data_schemas.session import Session
from data_schemas.stamps import ns_from_stamp

_BOUND = re.compile(r"^(?:(?P<s>\d+(?:\.\d*)?|\.\d+)s|m(?P<m>\d+))$")


class WindowError(BslamError):
    """A ``--from`` / ``--to`` bound that is malformed or that the log does not reach."""


@dataclass(frozen=True)
class Bound:
    """One end of a window: ``seconds`` after the log's first message, or a ``movement`` index."""

    seconds: float | None = None
    movement: int | None = None

    def __str__(self) -> str:
        return f"m{self.movement}" if self.movement is not None else f"{self.seconds:g}s"


def parse_bound(text: str) -> Bound:
    """``"12.5s"`` -> seconds, ``"m3"`` -> movement 3.

    Raises
    ------
    WindowError
        Anything else (a bare number says which unit to add).
    """
    found = _BOUND.match(text.strip())
    if found is None:
        raise WindowError(
            f"{text!r} is not a bound: write seconds from the log's start as '12.5s' or a "
            "movement as 'm3'"
        )
    if found["m"] is not None:
        return Bound(movement=int(found["m"]))
    seconds = float(found["s"])
    if not math.isfinite(seconds):
        raise WindowError(f"{text!r}: seconds must be finite")
    return Bound(seconds=seconds)


@dataclass(frozen=True)
class LogWindow:
    """``--from`` and ``--to`` (either may be None: the log's start or end)."""

    start: Bound | None = None
    end: Bound | None = None

    def __bool__(self) -> bool:
        return self.start is not None or self.end is not None

    def __str__(self) -> str:
        return f"{self.start or 'start'} .. {self.end or 'end'}"

    def range_ns(self, log: ProcessableLog) -> tuple[int | None, int | None]:
        """``[start_ns, end_ns)`` in log time for ``log`` (None: open on that side).

        Raises
        ------
        WindowError
            A movement the log does not have, or a window that ends before it starts.
        """
        first_ns = next((m.log_time_ns for m in log.messages()), 0)
        start_ns = None if self.start is None else self._at(log, self.start, first_ns, "start")
        end_ns = None if self.end is None else self._at(log, self.end, first_ns, "end") + 1
        if start_ns is not None and end_ns is not None and end_ns <= start_ns:
            raise WindowError(f"{log.name}: --from {self.start} is not before --to {self.end}")
        return start_ns, end_ns

    @staticmethod
    def _at(log: ProcessableLog, bound: Bound, first_ns: int, phase: str) -> int:
        """The log time of ``bound``: the first (``start``) or last (``end``) included."""
        if bound.movement is None:
            assert bound.seconds is not None
            return first_ns + round(bound.seconds * 1e9)
        times = []
        keyframe_ns = None
        indices = set()
        for msg in log.messages([MOVEMENT_TOPIC]):
            doc = msg.decode()
            indices.add(doc["index"])
            if doc["index"] == bound.movement and doc["phase"] == phase:
                times.append(msg.log_time_ns)
                keyframe_ns = ns_from_stamp(doc["keyframe_timestamp"])
        if not times or keyframe_ns is None:
            has = f"movements m{min(indices)} to m{max(indices)}" if indices else "no movements"
            raise WindowError(
                f"{log.name} has no {phase} of movement {bound.movement} (it has {has})"
            )
        # the keyframe itself (logged just before its movement message) is in the window
        times += [
            m.log_time_ns for m in log.messages([CAMERA_TOPIC], publish_times_ns={keyframe_ns})
        ]
        return min(times) if phase == "start" else max(times)


class WindowedLog:
    """The messages of ``log`` in a window: a :class:`data_schemas.mcap.open.MessageLog`.

    Attributes
    ----------
    start_ns, end_ns : int or None
        The log-time range kept, ``[start_ns, end_ns)``.
    """

    def __init__(self, log: ProcessableLog, window: LogWindow) -> None:
        self.log = log
        self.name: str = log.name
        self.path: Path = log.path
        self.session: Session = log.session
        self.start_ns, self.end_ns = window.range_ns(log)

    def messages(self, topics: Collection[str] | None = None) -> Iterator[LogMessage]:
        """Messages of ``topics`` in the window, in log-time order."""
        return self.log.messages(topics, start_ns=self.start_ns, end_ns=self.end_ns)
