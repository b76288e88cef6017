"""The one path from any importer to a log file: claimed first, written whole, then renamed.

The output is claimed against the importer's inputs before anything is read
(:class:`data_schemas.outputs.OutputGuard`), the log is written to a temporary file beside it
through :class:`data_schemas.mcap.writer.LogWriter` (every message validated against its schema)
and renamed into place only when complete: an interrupted import leaves no half log.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass

from data_schemas.mcap.writer import LogWriter
from data_schemas.outputs import OutputGuard
from replay.importers.source import Importer

#: Messages between two progress calls.
PROGRESS_EVERY = 5_000


class _SourceClock:
    """``log_time`` of an imported message: its sensor time (the source has no other)."""

    def __init__(self) -> None:
        self.now_ns = 0

    def monotonic_ns(self) -> int:
        return self.now_ns


@dataclass(frozen=True)
class ImportResult:
    """What an import wrote: message counts by topic, and the importer's notes."""

    path: str
    counts: dict[str, int]
    notes: list[str]


def import_log(
    importer: Importer,
    out: str | os.PathLike[str],
    *,
    force: bool = False,
    progress: Callable[[int, int], None] | None = None,
) -> ImportResult:
    """Read ``importer``'s source and write it to the log ``out``.

    Parameters
    ----------
    importer : Importer
        A format's importer (e.g. :class:`replay.importers.csv_files.CsvImporter`).
    out : path
        The log to write (MCAP).
    force : bool
        Replace an existing ``out`` (never one of the inputs).
    progress : callable (done, total), optional
        Called as messages are written.

    Raises
    ------
    OutputError
        ``out`` is an input, exists without ``force``, or cannot be written.
    ImportSourceError
        An input is missing or malformed (nothing is written).
    """
    guard = OutputGuard([f.path for f in importer.inputs], force=force)
    guard.claim(out, what="log")
    imported = importer.read()
    counts: dict[str, int] = {}
    total = imported.total
    clock = _SourceClock()
    with guard.staged(out) as tmp, LogWriter(tmp, imported.session_doc, clock=clock) as log:
        for done, msg in enumerate(imported.messages, start=1):
            clock.now_ns = msg.t_ns
            log.write(msg.topic, msg.doc)
            counts[msg.topic] = counts.get(msg.topic, 0) + 1
            if progress is not None and (done % PROGRESS_EVERY == 0 or done == total):
                progress(done, total)
    return ImportResult(os.fspath(out), counts, imported.notes)
