"""Shared tail of ``bslam record`` and ``bslam simulate``: run the recorder with progress."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar

import click

if TYPE_CHECKING:
    from recorder.record import Progress, RecordResult
    from replay.live import LiveView

F = TypeVar("F", bound=Callable[..., Any])
#: After the recording, how long to let the live view read to the end of the log (seconds).
LIVE_WAIT_S = 60.0


def frame_options(func: F) -> F:
    """The frame-capture options shared by ``record`` and ``simulate``.

    Adds ``--rate`` (``frame_rate_hz``), ``--encoding`` and ``--png-level``.
    """
    for option in reversed(
        (
            click.option(
                "--rate",
                "frame_rate_hz",
                type=click.FloatRange(min=0, min_open=True),
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


def live_options(func: F) -> F:
    """``--live`` and its Rerun targets ``--spawn``, ``--connect URL``, ``--save X.rrd``."""
    for option in reversed(
        (
            click.option(
                "--live",
                is_flag=True,
                help="Show the map while recording, from a separate follower process: a compact "
                "terminal view, or Rerun with --spawn, --connect or --save.",
            ),
            click.option("--spawn", is_flag=True, help="With --live: start a Rerun viewer."),
            click.option(
                "--connect",
                metavar="URL",
                help="With --live: stream to a running Rerun viewer.",
            ),
            click.option(
                "--save",
                "save_rrd",
                metavar="X.rrd",
                type=click.Path(dir_okay=False),
                help="With --live: write the live Rerun recording to X.rrd.",
            ),
        )
    ):
        func = option(func)
    return func


def live_view(
    live: bool, spawn: bool, connect: str | None, save_rrd: str | None
) -> LiveView | None:
    """The live view the options ask for (None without --live); usage error if they clash."""
    from replay.live import LiveView

    chosen = [k for k, v in (("spawn", spawn), ("connect", connect), ("save", save_rrd)) if v]
    if chosen and not live:
        raise click.UsageError(f"--{chosen[0]} shows a live view: add --live")
    if len(chosen) > 1:
        raise click.UsageError(f"choose one of --spawn, --connect, --save (got {chosen})")
    if not live:
        return None
    if not chosen:
        return LiveView("terminal")
    return LiveView(chosen[0], connect or save_rrd)  # type: ignore[arg-type]


def run_recording(
    out: str | os.PathLike[str],
    record: Callable[[Callable[[Progress], None]], RecordResult],
    *,
    total: int | None,
    live: LiveView | None = None,
) -> None:
    """Run ``record(progress)`` with a progress bar on stderr; report the result on stdout.

    ``record`` is a library call that writes the log ``out`` and reports each movement to the
    callback it is given (:func:`recorder.record.record_to_file`,
    :func:`recorder.sim.simulate.simulate_to_file`); ``total`` is the number of moves for the bar
    (None: unknown). A stop request (SIGINT/SIGTERM) finishes the log and exits with 128 + the
    signal number. ``live``: a follower process shows the log as it grows
    (:class:`replay.live.LiveFollower`; the terminal view replaces the progress bar); if it
    fails, the recording goes on and says so once.
    """
    from tqdm import tqdm

    from recorder.record import RecordingInterrupted

    follower = None
    if live is not None:
        from replay.live import LiveFollower

        follower = LiveFollower(live, out)
    quiet = live is not None and live.kind == "terminal"
    try:
        with tqdm(
            total=total, unit="move", file=sys.stderr, desc="recording", disable=quiet
        ) as bar:

            def progress(p: Progress) -> None:
                bar.update(p.movements - bar.n)
                bar.set_postfix(frames=p.frames)
                line = follower.check() if follower is not None else None
                if line:
                    tqdm.write(line, file=sys.stderr)

            try:
                result = record(progress)
            except RecordingInterrupted as exc:
                bar.close()
                click.echo(f"{exc}; {os.fspath(out)} is finished and indexed", err=True)
                click.get_current_context().exit(128 + exc.signum)
    finally:
        if follower is not None:
            line = follower.wait(LIVE_WAIT_S)
            if line:
                click.echo(line, err=True)
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
