"""Shared tail of ``bslam record`` and ``bslam simulate``: run the recorder with progress."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING

import click

if TYPE_CHECKING:
    from recorder.record import Progress, RecordResult


def run_recording(
    out: str | os.PathLike[str],
    record: Callable[[Callable[[Progress], None]], RecordResult],
    *,
    total: int | None,
) -> None:
    """Run ``record(progress)`` with a progress bar on stderr; report the result on stdout.

    ``record`` is a library call that writes the log ``out`` and reports each movement to the
    callback it is given (:func:`recorder.record.record_to_file`,
    :func:`recorder.sim.simulate.simulate_to_file`); ``total`` is the number of moves for the bar
    (None: unknown). A stop request (SIGINT/SIGTERM) finishes the log and exits with 128 + the
    signal number.
    """
    from tqdm import tqdm

    from recorder.record import RecordingInterrupted

    with tqdm(total=total, unit="move", file=sys.stderr, desc="recording") as bar:

        def progress(p: Progress) -> None:
            bar.update(p.movements - bar.n)
            bar.set_postfix(frames=p.frames)

        try:
            result = record(progress)
        except RecordingInterrupted as exc:
            bar.close()
            click.echo(f"{exc}; {os.fspath(out)} is finished and indexed", err=True)
            click.get_current_context().exit(128 + exc.signum)
    click.echo(f"wrote {os.fspath(out)}: {result.movements} movements, {result.frames} frames")
