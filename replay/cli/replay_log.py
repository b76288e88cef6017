"""``bslam replay``: every stage of one log in the Rerun viewer."""

from __future__ import annotations

import shlex
import time
from pathlib import Path

import click

from replay.cli.process import method_options, show_skips


@click.command("replay")
@click.argument("log", type=click.Path(path_type=Path))
@click.option("--save", "save", type=click.Path(path_type=Path), help="Write a .rrd file.")
@click.option("--spawn", is_flag=True, help="Start a Rerun viewer and stream to it.")
@click.option(
    "--connect",
    metavar="URL",
    help="Stream to a running viewer (e.g. rerun+http://127.0.0.1:9876/proxy).",
)
@click.option("--serve", is_flag=True, help="Serve the recording (gRPC + web viewer) until Ctrl-C.")
@click.option("--keyframes-only", is_flag=True, help="Skip the frames between keyframes.")
@method_options
def replay(
    log: Path,
    save: Path | None,
    spawn: bool,
    connect: str | None,
    serve: bool,
    keyframes_only: bool,
    prior: str,
    n_r: int,
    n_l: int,
    seed: int,
) -> None:
    """Stream every stage of LOG to Rerun: panorama, masks, bearings, cones, particles, map.

    Without a target option it saves LOG's name with .rrd in the current folder.
    """
    from replay.cli.recording import viewer_command
    from replay.logs import ProcessableLog
    from replay.process import result_line
    from replay.records import MethodConfig
    from replay.rerun_out import RerunTarget, open_recording, replay_log

    chosen = [
        k
        for k, v in (("save", save), ("spawn", spawn), ("connect", connect), ("serve", serve))
        if v
    ]
    if len(chosen) > 1:
        raise click.UsageError(f"choose one of --save, --spawn, --connect, --serve (got {chosen})")
    if not chosen:
        save = Path(log.stem + ".rrd")
    where = str(save) if save else connect
    target = RerunTarget(chosen[0] if chosen else "save", where)  # type: ignore[arg-type]
    method = MethodConfig(prior=prior, n_r=n_r, n_l=n_l, seed=seed)
    with ProcessableLog(log) as opened:  # a bad log fails here, before any output exists
        rec, url = open_recording(log.stem, target)
        try:
            with show_skips():
                doc = replay_log(opened, method, rec, images=not keyframes_only)
        finally:
            if not serve:
                rec.disconnect()
    click.echo(f"{log}: {result_line(doc)}")
    if save:
        click.echo(f"wrote {save}; open it with: {shlex.join([viewer_command(), str(save)])}")
    if serve:
        import rerun as rr

        rr.serve_web_viewer(connect_to=url, open_browser=False)
        click.echo(f"serving {url} (web viewer: http://localhost:9090); Ctrl-C to stop")
        try:
            while True:
                time.sleep(1.0)
        except KeyboardInterrupt:
            rec.disconnect()
