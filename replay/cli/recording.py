"""Shared tail of ``bslam record`` and ``bslam simulate``: run the recorder with progress."""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import click

from data_schemas.registry import IMAGE_SCHEMA
from replay.cli.options import FiniteFloat

if TYPE_CHECKING:
    from recorder.record import Progress, RecordResult
    from replay.live import LiveView

F = TypeVar("F", bound=Callable[..., Any])
#: After the recording, how long to let the live view read to the end of the log (seconds).
LIVE_WAIT_S = 60.0


def frame_options(func: F) -> F:
    """The frame-capture options shared by ``record`` and ``simulate``.

    Adds ``--rate`` (``frame_rate_hz``), ``--encoding``, ``--png-level``,
    ``--chunk-compression`` and ``--force``.
    """
    for option in reversed(
        (
            click.option(
                "--rate",
                "frame_rate_hz",
                type=FiniteFloat(min=0, min_open=True, max=1000),
                default=5.0,
                show_default=True,
                help="Frames per second while driving (virtual time when simulating).",
            ),
            click.option(
                "--encoding",
                type=click.Choice(list(IMAGE_SCHEMA)),
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
            click.option(
                "--chunk-compression",
                type=click.Choice(["none", "zstd"]),
                default="none",
                show_default=True,
                help="Compress log chunks (zstd pays off for bgr8 frames, not for PNG).",
            ),
            click.option(
                "--force",
                is_flag=True,
                help="Replace an existing --out (record moves the old log to NAME.old-N.mcap).",
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
    from replay.extras import require_viewer

    require_viewer(f"--live --{chosen[0]}")
    return LiveView(chosen[0], connect or save_rrd)  # type: ignore[arg-type]


def run_recording(
    out: str | os.PathLike[str],
    record: Callable[[Path, Callable[[Progress], None]], RecordResult],
    *,
    total: int | None,
    force: bool = False,
    inputs: Sequence[str | os.PathLike[str]] = (),
    staged: bool = False,
    live: LiveView | None = None,
) -> None:
    """Run ``record(path, progress)`` with a progress bar on stderr; report on stdout.

    ``record`` is a library call that writes the log at ``path`` and reports each movement to
    the callback it is given (:func:`recorder.record.record_to_file`,
    :func:`recorder.sim.simulate.simulate_to_file`); ``total`` is the number of moves for the bar
    (None: unknown). A stop request (SIGINT/SIGTERM) finishes the log and exits with 128 + the
    signal number.

    ``out`` is checked first (:class:`data_schemas.outputs.OutputGuard`). ``staged`` (a log
    that can be made again, as the demo's): it is written beside ``out`` and renamed onto it
    when finished. Otherwise (a
    recording, whose log must be on disk as it grows) an existing ``out`` is moved aside to
    ``NAME.old-N.mcap`` (``force`` only), never overwritten, and the name is created
    exclusively (:func:`data_schemas.outputs.create_new`: a second process given the same
    ``out`` refuses).

    ``live``: a follower process shows the log as it grows (:class:`replay.live.LiveFollower`;
    the terminal view replaces the progress bar), reading the log at ``out`` itself (so a live
    log is never staged); if the follower fails, the recording goes on and says so once.
    """
    from tqdm import tqdm

    from data_schemas.outputs import OutputGuard, create_new, move_aside
    from recorder.record import RecordingInterrupted

    guard = OutputGuard(inputs, force=force)
    guard.claim(out, what="log")
    interrupted: RecordingInterrupted | None = None
    quiet = live is not None and live.kind == "terminal"
    with contextlib.ExitStack() as stack:
        if staged and live is None:
            path = stack.enter_context(guard.staged(out))
        else:
            path = Path(out)
            aside = move_aside(path)
            if aside is not None:
                click.echo(f"moved the existing {os.fspath(out)} aside to {aside}", err=True)
            stack.enter_context(create_new(path))  # the name is ours: no other writer
        follower = None
        if live is not None:
            from replay.live import LiveFollower

            follower = LiveFollower(live, path)
        try:
            # delay: a session that fails at once (a bad file, no robot) leaves one line, no bar
            with tqdm(
                total=total,
                unit="move",
                file=sys.stderr,
                desc="recording",
                disable=True if quiet else None,  # None: only on a terminal
                delay=0.5,
            ) as bar:

                def progress(p: Progress) -> None:
                    bar.update(p.movements - bar.n)
                    bar.set_postfix(frames=p.frames)
                    line = follower.check() if follower is not None else None
                    if line:
                        tqdm.write(line, file=sys.stderr)

                try:
                    result = record(path, progress)
                except RecordingInterrupted as exc:
                    interrupted = exc  # the log is finished: keep it
        finally:
            if follower is not None:
                line = follower.wait(LIVE_WAIT_S)
                if line:
                    click.echo(line, err=True)
    if interrupted is not None:
        click.echo(f"{interrupted}; {os.fspath(out)} is finished and indexed", err=True)
        click.get_current_context().exit(128 + interrupted.signum)
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


def viewing_hints(rrd: Path) -> list[str]:
    """How to look at the Rerun recording ``rrd``: with a display, and without one."""
    import shlex

    viewer = viewer_command()
    return [
        f"wrote {rrd}; open it with: {shlex.join([viewer, str(rrd)])}",
        "no display here (a robot, a server)? serve it to a browser: "
        f"{shlex.join([viewer, '--serve-web', str(rrd)])}, then open http://HOST:9090 "
        "(HOST: this machine's name)",
    ]
