"""Shared tail of ``bslam record`` and ``bslam simulate``: run the recorder with progress."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar

import click

from replay.cli.options import FiniteFloat

if TYPE_CHECKING:
    from recorder.record import Progress, RecordResult

F = TypeVar("F", bound=Callable[..., Any])


def frame_options(func: F) -> F:
    """The frame-capture options shared by ``record`` and ``simulate``.

    Adds ``--rate`` (``frame_rate_hz``), ``--encoding`` and ``--png-level``.
    """
    for option in reversed(
        (
            click.option(
                "--rate",
                "frame_rate_hz",
                type=FiniteFloat(min=0, min_open=True),
                default=5.0,
                show_default=True,
                help="Frames per second while driving (virtual time when simulating).",
            ),
            click.option(
                "--encoding",
                type=click.Choice(["png", "bgr8"]),
                default="png",
                show_default=True,
                help="Frame storage (both lossless).",
            ),
            click.option(
                "--png-level",
                type=click.IntRange(0, 3),
                default=1,
                show_default=True,
                help="PNG compression: 0 stored (fastest), 1 fast (half size), up to 3.",
            ),
        )
    ):
        func = option(func)
    return func


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

    # delay: a session that fails at once (a bad file, no robot) leaves one line, no bar
    bar = tqdm(total=total, unit="move", file=sys.stderr, desc="recording", delay=0.5)
    with bar:

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


def viewer_command() -> str:
    """How to start the Rerun viewer from this environment.

    ``rerun`` if it is on PATH, else the viewer installed beside this Python (a venv that is not
    activated, as in the README's set-up).
    """
    import shutil
    from pathlib import Path

    if shutil.which("rerun"):
        return "rerun"
    beside = Path(sys.executable).parent / "rerun"
    return str(beside) if beside.exists() else "rerun"
