"""``bslam replay``: every stage of one log in the Rerun viewer."""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING

import click

from replay.cli.follow import end_of_follow, follow_options
from replay.cli.options import method_options, window_options
from replay.cli.process import show_skips

if TYPE_CHECKING:
    from data_schemas.mcap.window import Bound
    from replay.records import MethodConfig


@click.command("replay")
@click.argument("log", type=click.Path(path_type=Path))
@click.option("--save", "save", type=click.Path(path_type=Path), help="Write a .rrd file.")
@click.option("--spawn", is_flag=True, help="Start a Rerun viewer and stream to it.")
@click.option(
    "--connect",
    metavar="URL",
    help="Stream to a running viewer (e.g. rerun+http://127.0.0.1:9876/proxy).",
)
@click.option(
    "--serve",
    is_flag=True,
    help="Serve the recording (gRPC + web viewer, on every interface) until Ctrl-C: "
    "for a machine without a display.",
)
@click.option(
    "--host",
    metavar="NAME",
    help="--serve: the name or address other machines reach this one by, put in the printed "
    "URLs.  [default: this machine's host name]",
)
@click.option(
    "--port",
    type=click.IntRange(1, 65535),
    help="--serve: the recording's gRPC port.  [default: 9876]",
)
@click.option(
    "--web-port",
    type=click.IntRange(1, 65535),
    help="--serve: the web viewer's HTTP port.  [default: 9090]",
)
@click.option("--keyframes-only", is_flag=True, help="Skip the frames between keyframes.")
@click.option("--force", is_flag=True, help="Replace an existing --save file (never LOG).")
@click.option(
    "--skip-corrupt",
    is_flag=True,
    help="Replay a corrupt log without its damaged chunks (warned) instead of refusing it.",
)
@window_options
@method_options
@follow_options
def replay(
    log: Path,
    save: Path | None,
    spawn: bool,
    connect: str | None,
    serve: bool,
    host: str | None,
    port: int | None,
    web_port: int | None,
    keyframes_only: bool,
    force: bool,
    skip_corrupt: bool,
    start: Bound | None,
    end: Bound | None,
    method: MethodConfig,
    follow: bool,
    idle_timeout: float,
) -> None:
    """Stream every stage of LOG to Rerun: panorama, masks, bearings, cones, particles, map.

    Without a target option it saves LOG's name with .rrd in the current folder. With --follow,
    LOG is still being written: movements are streamed as their chunks reach the disk, the
    viewer follows the latest movement, and the command ends when LOG is finished (exit 0) or
    idle for --idle-timeout seconds (exit 1).

    On a machine without a display (a robot), --serve and open the printed web viewer URL in a
    browser elsewhere, or --save and view the file with `rerun --serve-web FILE.rrd`.
    """
    import socket

    from replay.extras import require_viewer

    require_viewer("bslam replay")
    from data_schemas.mcap.follow import FollowedLog
    from data_schemas.mcap.open import open_log
    from data_schemas.mcap.processable import ProcessableLog
    from data_schemas.mcap.window import LogWindow
    from replay.cli.recording import viewing_hints
    from replay.process import result_line, windowed
    from replay.rerun_out import (
        DEFAULT_GRPC_PORT,
        DEFAULT_WEB_PORT,
        RerunTarget,
        ServeAddress,
        open_recording,
        recording_id,
        replay_log,
        save_rrd,
        serve_web_viewer,
    )
    from replay.sinks.progress import ProgressSink

    chosen = [
        k
        for k, v in (("save", save), ("spawn", spawn), ("connect", connect), ("serve", serve))
        if v
    ]
    if len(chosen) > 1:
        raise click.UsageError(f"choose one of --save, --spawn, --connect, --serve (got {chosen})")
    if not chosen:
        save = Path(log.stem + ".rrd")
    window = LogWindow(start, end)
    if follow and window:
        raise click.UsageError("--from/--to take a finished log, not --follow")
    if not serve and (host, port, web_port) != (None, None, None):
        raise click.UsageError("--host, --port and --web-port go with --serve")
    address = ServeAddress(
        host or socket.gethostname(),
        DEFAULT_GRPC_PORT if port is None else port,
        DEFAULT_WEB_PORT if web_port is None else web_port,
    )
    with show_skips():
        # a bad log fails here, before any output exists
        opened: FollowedLog | ProcessableLog = (
            open_log(log, follow=True, idle_timeout_s=idle_timeout)
            if follow
            else open_log(log, skip_corrupt=skip_corrupt)
        )
        with opened:
            source = windowed(opened, window) if window else opened
            bars = () if follow else (ProgressSink.for_log(log, window),)
            if save:
                doc = save_rrd(
                    source,
                    method,
                    save,
                    force=force,
                    images=not keyframes_only,
                    extra_sinks=bars,
                )
            else:
                target = RerunTarget(
                    chosen[0],  # type: ignore[arg-type]
                    connect,
                    port=address.grpc_port,
                )
                rec, _ = open_recording(recording_id(opened), target, live=follow)
                if serve:
                    serve_web_viewer(address)
                    click.echo(f"web viewer: {address.web_url}")
                    click.echo(f"native viewer: rerun {address.grpc_url}")
                try:
                    doc = replay_log(
                        source,
                        method,
                        rec,
                        images=not keyframes_only,
                        live=follow,
                        extra_sinks=bars,
                    )
                finally:
                    if not serve:
                        rec.disconnect()
    click.echo(f"{log}: {result_line(doc)}")
    if save:
        for line in viewing_hints(save):
            click.echo(line)
    if isinstance(opened, FollowedLog) and not serve:
        end_of_follow(opened)
    if serve:
        click.echo(f"serving until Ctrl-C: {address.web_url}")
        try:
            while True:
                time.sleep(1.0)
        except KeyboardInterrupt:
            rec.disconnect()
