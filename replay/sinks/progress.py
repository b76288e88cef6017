"""A progress bar over a log's movements (stderr, shown only on a terminal), as a sink.

``bslam process`` (one log), ``replay --save`` and ``demo`` run one log for seconds without a
word; this sink moves a tqdm bar at each movement. tqdm draws nothing when stderr is not a
terminal (``disable=None``), so pipes and CI logs stay clean.
"""

from __future__ import annotations

import os
import sys
from typing import Any

from tqdm import tqdm

from data_schemas.errors import BslamError
from data_schemas.mcap.open import open_log
from data_schemas.mcap.window import LogWindow, WindowedLog
from data_schemas.registry import MOVEMENT_TOPIC
from replay.records import AssociationRecord, FrameRecord, MovementRecord, RunInfo


def progress_bar(**kwargs: Any) -> tqdm[Any]:
    """A tqdm bar on stderr, drawn only if stderr is a terminal, after half a second."""
    kwargs.setdefault("delay", 0.5)
    kwargs.setdefault("disable", None)  # tqdm: None disables on a stream that is not a tty
    return tqdm(file=sys.stderr, **kwargs)


def movement_count(log: str | os.PathLike[str], window: LogWindow | None = None) -> int | None:
    """How many movements end in ``log`` (within ``window``); None if it cannot tell."""
    try:
        with open_log(log, warn=False) as opened:
            source = WindowedLog(opened, window) if window else opened
            return sum(
                bool(m.decode()["phase"] == "end") for m in source.messages([MOVEMENT_TOPIC])
            )
    except BslamError:
        return None  # the run itself reports what is wrong with the log


class ProgressSink:
    """Moves a bar by one at each movement (``total``: the movements expected, if known)."""

    wants_all_frames = False
    wants_images = False

    def __init__(self, total: int | None = None, desc: str = "movements") -> None:
        self._bar = progress_bar(total=total, desc=desc, unit="move")

    @classmethod
    def for_log(cls, log: str | os.PathLike[str], window: LogWindow | None = None) -> ProgressSink:
        """A bar for ``log``; its movements are counted first only when the bar will show."""
        total = movement_count(log, window) if sys.stderr.isatty() else None
        return cls(total)

    def start(self, run: RunInfo) -> None:
        self._bar.set_description(run.log_name)

    def frame(self, frame: FrameRecord) -> None:
        """Frames do not move the bar."""

    def movement(self, record: MovementRecord) -> None:
        self._bar.update(1)

    def association(self, record: AssociationRecord) -> None:
        """The final association does not move the bar."""

    def finish(self) -> None:
        self._bar.close()
