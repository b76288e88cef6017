"""Split a log into parts and merge parts (or a log and its derived log) into one.

Both write through :class:`~data_schemas.mcap.writer.LogWriter`: every message keeps its log time
and time stamp and is validated again, and each output opens with a session document.

* :func:`split_log` cuts a log at bounds (``--at m5``, ``--at 60s``, as ``--from``): each part
  keeps the session document unchanged, so the parts are logs of the same session.
* :func:`merge_logs` interleaves logs *of one session* in log-time order: the parts of a split,
  or a log with its derived log (one file for Foxglove). Logs of different sessions are refused
  (their movement indices and times would mix), and so is one topic coming from two inputs over
  overlapping times (a log merged with itself, say). The output's session document is the first
  input's, with the ``derived`` block of the first input that has one.
"""

from __future__ import annotations

import contextlib
import heapq
import itertools
import json
import os
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from data_schemas.errors import BslamError
from data_schemas.mcap.open import open_log
from data_schemas.mcap.processable import ProcessableLog
from data_schemas.mcap.read import LogMessage
from data_schemas.mcap.window import Bound, LogWindow
from data_schemas.mcap.writer import LogWriter, SettableClock
from data_schemas.outputs import OutputGuard

PathLike = str | os.PathLike[str]


class PartsError(BslamError):
    """Logs that cannot be split that way or merged."""


#: Called with the number of messages written so far (a progress bar).
Progress = Callable[[int], object]


def _copy(
    messages: Iterator[LogMessage],
    writer: LogWriter,
    clock: SettableClock,
    progress: Progress | None = None,
) -> int:
    count = 0
    for msg in messages:
        clock.t_ns = msg.log_time_ns
        writer.write(msg.topic, json.loads(msg.data), schema=msg.schema)
        count += 1
        if progress is not None:
            progress(1)
    return count


def part_paths(log: PathLike, n: int, out_dir: PathLike | None = None) -> list[Path]:
    """Where :func:`split_log` writes ``n`` parts of ``log``: ``NAME.part1.mcap`` ... beside it
    (or in ``out_dir``)."""
    source = Path(log)
    folder = source.parent if out_dir is None else Path(out_dir)
    return [folder / f"{source.stem}.part{k}{source.suffix}" for k in range(1, n + 1)]


def _cut_ns(log: ProcessableLog, bound: Bound) -> int:
    start_ns, _ = LogWindow(start=bound).range_ns(log)
    assert start_ns is not None
    return start_ns


def split_log(
    log: PathLike,
    at: Sequence[Bound],
    outs: Sequence[PathLike],
    *,
    force: bool = False,
    progress: Progress | None = None,
) -> list[int]:
    """Cut ``log`` at the bounds ``at`` (in order) into ``len(at) + 1`` logs ``outs``.

    A part ends just before the next one starts: ``--at m5`` puts movement 5 (from its start
    keyframe) and what follows in the second part. Returns each part's message count;
    ``progress`` is called with 1 after each message written.

    Raises
    ------
    PartsError
        Bounds not in increasing order, or not as many outputs as parts.
    WindowError, OutputError, LogError
        A bound the log does not reach; an output that is an input or exists without ``force``;
        a log that cannot be read.
    """
    if len(outs) != len(at) + 1:
        raise PartsError(f"{len(at)} cut(s) make {len(at) + 1} parts, got {len(outs)} outputs")
    guard = OutputGuard([log], force=force)
    for out in outs:
        guard.claim(out, what="part of the log")
    with open_log(log) as source:
        cuts = [_cut_ns(source, b) for b in at]
        if any(b <= a for a, b in itertools.pairwise(cuts)):
            raise PartsError(
                f"{source.name}: cut points must increase (got {', '.join(map(str, at))})"
            )
        edges: list[int | None] = [None, *cuts, None]
        counts = []
        with contextlib.ExitStack() as stack:
            staged = [stack.enter_context(guard.staged(out)) for out in outs]
            for k, path in enumerate(staged):
                clock = SettableClock()
                with LogWriter(path, source.session.doc, clock=clock, fsync=False) as writer:
                    part = source.messages(start_ns=edges[k], end_ns=edges[k + 1])
                    counts.append(_copy(part, writer, clock, progress))
    return counts


def _session_doc(logs: Sequence[ProcessableLog]) -> dict[str, Any]:
    ids = {log.session.session_id for log in logs}
    if len(ids) > 1:
        names = ", ".join(log.name for log in logs)
        raise PartsError(
            f"{names}: logs of different sessions cannot be merged (their movement indices and "
            "times would mix); merge the parts of one log, or a log and its derived log"
        )
    doc = dict(logs[0].session.doc)
    derived = next(
        (log.session.doc["derived"] for log in logs if "derived" in log.session.doc), None
    )
    if derived is not None:
        doc["derived"] = derived
    return doc


def _check_no_overlap(logs: Sequence[ProcessableLog]) -> None:
    """One topic from two inputs must not overlap in time (a log given twice, say)."""
    spans: dict[str, list[tuple[int, int, str]]] = {}
    for log in logs:
        times: dict[str, list[int]] = {}
        for msg in log.messages():
            times.setdefault(msg.topic, []).append(msg.log_time_ns)
        for topic, t in times.items():
            spans.setdefault(topic, []).append((min(t), max(t), log.name))
    for topic, found in spans.items():
        found.sort()
        for (_, end, a), (start, _, b) in itertools.pairwise(found):
            if start <= end:
                raise PartsError(
                    f"{a} and {b} both have {topic} messages over the same time; merge logs "
                    "whose messages do not overlap (the parts of a split, a log and its "
                    "derived log)"
                )


def merge_logs(
    logs: Sequence[PathLike],
    out: PathLike,
    *,
    force: bool = False,
    progress: Progress | None = None,
) -> int:
    """Merge logs of one session into ``out``, in log-time order; return the message count
    (``progress`` is called with 1 after each message written).

    Raises
    ------
    PartsError
        Fewer than two logs, logs of different sessions, or one topic from two logs over
        overlapping times.
    OutputError, LogError
        ``out`` is an input or exists without ``force``; a log that cannot be read.
    """
    if len(logs) < 2:
        raise PartsError("merge takes two logs or more")
    guard = OutputGuard(logs, force=force)
    guard.claim(out, what="merged log")
    with contextlib.ExitStack() as stack:
        opened = [stack.enter_context(open_log(log)) for log in logs]
        doc = _session_doc(opened)
        _check_no_overlap(opened)
        staged = stack.enter_context(guard.staged(out))
        clock = SettableClock()
        with LogWriter(staged, doc, clock=clock, fsync=False) as writer:
            streams = [log.messages() for log in opened]
            merged = heapq.merge(*streams, key=lambda m: m.log_time_ns)
            return _copy(merged, writer, clock, progress)
