"""``bslam split`` and ``bslam merge``: parts of a log, and logs of one session made one."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

from replay.cli.options import WindowBound

if TYPE_CHECKING:
    from data_schemas.mcap.window import Bound


@click.command("split")
@click.argument("log", type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "--at",
    "at",
    type=WindowBound(),
    multiple=True,
    required=True,
    help="Cut here (repeat for more): a movement ('m5': it starts the next part) or seconds "
    "from the log's start ('60s').",
)
@click.option(
    "--out-dir",
    type=click.Path(file_okay=False, path_type=Path),
    help="Folder of the parts [default: beside LOG].",
)
@click.option("--force", is_flag=True, help="Replace existing parts (never LOG).")
def split(log: Path, at: tuple[Bound, ...], out_dir: Path | None, force: bool) -> None:
    """Cut LOG into parts NAME.part1.mcap, NAME.part2.mcap, ... at the --at points.

    Each part is a log of the same session (its session metadata kept), so it can be
    processed, replayed or merged back.
    """
    from data_schemas.mcap.parts import part_paths, split_log
    from replay.sinks.progress import progress_bar

    outs = part_paths(log, len(at) + 1, out_dir)
    with progress_bar(desc="splitting", unit="msg") as bar:
        counts = split_log(log, at, outs, force=force, progress=bar.update)
    for path, count in zip(outs, counts, strict=True):
        click.echo(f"wrote {path}: {count} messages")


@click.command("merge")
@click.argument("logs", nargs=-1, required=True, type=click.Path(dir_okay=False, path_type=Path))
@click.option("--out", type=click.Path(path_type=Path), required=True, help="Merged log.")
@click.option("--force", is_flag=True, help="Replace an existing --out (never a LOG).")
def merge(logs: tuple[Path, ...], out: Path, force: bool) -> None:
    """Merge LOGS of one session into one log, in log-time order.

    For the parts of a split, or a log and its derived log (`bslam process --out`): one file
    holds the frames and the map, for Foxglove. Logs of different sessions are refused.
    """
    from data_schemas.mcap.parts import merge_logs
    from replay.sinks.progress import progress_bar

    with progress_bar(desc="merging", unit="msg") as bar:
        count = merge_logs(logs, out, force=force, progress=bar.update)
    click.echo(f"wrote {out}: {count} messages from {len(logs)} logs")
