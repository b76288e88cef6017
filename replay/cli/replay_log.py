"""``bslam replay``: every stage of one log in the Rerun viewer."""

from __future__ import annotations

import shlex
import time
from pathlib import Path

import click

from replay.cli.follow import end_of_follow, follow_options
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
@click.option("--force", is_flag=True, help="Replace an existing --save file (never LOG).")
@click.option(
    "--skip-corrupt",
    is_flag=True,
    help="Replay a corrupt log without its damaged chunks (warned) instead of refusing it.",
)
@method_options
@follow_options
def replay(
    log: Path,
    save: Path | None,
    spawn: bool,
    connect: str | None,
    serve: bool,
    keyframes_only: bool,
    force: bool,
    skip_corrupt: bool,
    estimator: str,
    turn_prior_deg: float | None,
    distance_prior: float | None,
    prior: str,
    n_r: int,
    n_l: int,
    seed: int,
    follow: bool,
    idle_timeout: float,
) -> None:
    """Stream every stage of LOG to Rerun: panorama, masks, bearings, cones, particles, map.

    Without a target option it saves LOG's name with .rrd in the current folder. With --follow,
    LOG is still being written: movements are streamed as their chunks reach the disk, the
    viewer follows the latest movement, and the command ends when LOG is finished (exit 0) or
    idle for --idle-timeout seconds (exit 1).
    """
    from data_schemas.mcap.processable import ProcessableLog
    from replay.cli.recording import viewer_command
    from replay.follow import FollowedLog
    from replay.process import open_log, result_line
    from replay.records import MethodConfig
    from replay.rerun_out import RerunTarget, open_recording, recording_id, replay_log, save_rrd

    chosen = [
        k
        for k, v in (("save", save), ("spawn", spawn), ("connect", connect), ("serve", serve))
        if v
    ]
    if len(chosen) > 1:
        raise click.UsageError(f"choose one of --save, --spawn, --connect, --serve (got {chosen})")
    if not chosen:
        save = Path(log.stem + ".rrd")
    method = MethodConfig(
        prior=prior,
        n_r=n_r,
        n_l=n_l,
        seed=seed,
        estimator=estimator,
        turn_prior_deg=turn_prior_deg,
        distance_prior=distance_prior,
    )
    url = None
    with show_skips():
        # a bad log fails here, before any output exists
        opened: FollowedLog | ProcessableLog = (
            FollowedLog(log, idle_timeout_s=idle_timeout)
            if follow
            else open_log(log, skip_corrupt=skip_corrupt)
        )
        with opened:
            if save:
                doc = save_rrd(opened, method, save, force=force, images=not keyframes_only)
            else:
                target = RerunTarget(chosen[0], connect)  # type: ignore[arg-type]
                rec, url = open_recording(recording_id(opened), target, live=follow)
                try:
                    doc = replay_log(opened, method, rec, images=not keyframes_only, live=follow)
                finally:
                    if not serve:
                        rec.disconnect()
    click.echo(f"{log}: {result_line(doc)}")
    if save:
        click.echo(f"wrote {save}; open it with: {shlex.join([viewer_command(), str(save)])}")
    if isinstance(opened, FollowedLog) and not serve:
        end_of_follow(opened)
    if serve:
        import rerun as rr

        rr.serve_web_viewer(connect_to=url, open_browser=False)
        click.echo(f"serving {url} (web viewer: http://localhost:9090); Ctrl-C to stop")
        try:
            while True:
                time.sleep(1.0)
        except KeyboardInterrupt:
            rec.disconnect()
