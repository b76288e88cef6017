"""Shared tail of ``bslam record`` and ``bslam simulate``: run the recorder with progress."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

import click

if TYPE_CHECKING:
    from recorder.moves import Move
    from recorder.record import RecordSettings, Rig


def run_recording(
    out: str | os.PathLike[str],
    session_doc: dict[str, Any],
    rig: Rig,
    moves: Iterable[Move],
    settings: RecordSettings,
    *,
    total: int | None,
) -> None:
    """Record into ``out`` with a progress bar on stderr; report the result on stdout.

    ``total`` is the number of moves for the bar (None: unknown); the other arguments are
    those of :func:`recorder.record.record_to_file`. A stop request (SIGINT/SIGTERM) finishes
    the log and exits with 128 + the signal number.
    """
    from tqdm import tqdm

    from recorder.record import Progress, RecordingInterrupted, record_to_file

    with tqdm(total=total, unit="move", file=sys.stderr, desc="recording") as bar:

        def progress(p: Progress) -> None:
            bar.update(p.movements - bar.n)
            bar.set_postfix(frames=p.frames)

        try:
            result = record_to_file(out, session_doc, rig, moves, settings, progress=progress)
        except RecordingInterrupted as exc:
            bar.close()
            click.echo(f"{exc}; {os.fspath(out)} is finished and indexed", err=True)
            click.get_current_context().exit(128 + exc.signum)
    click.echo(f"wrote {os.fspath(out)}: {result.movements} movements, {result.frames} frames")
