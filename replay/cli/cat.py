"""``bslam cat LOG [--topic T]...``: a log's messages as JSON lines (like ``ros2 topic echo``)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import click

from replay.cli.options import window_options

if TYPE_CHECKING:
    from data_schemas.mcap.window import Bound


@click.command("cat")
@click.argument("log", type=click.Path(dir_okay=False))
@click.option(
    "--topic",
    "topics",
    multiple=True,
    metavar="TOPIC",
    help="Only this topic (repeat for more) [default: every topic].",
)
@window_options
@click.option(
    "--data", "with_bytes", is_flag=True, help="Print frames' and point clouds' bytes too."
)
def cat(
    log: str,
    topics: tuple[str, ...],
    start: Bound | None,
    end: Bound | None,
    with_bytes: bool,
) -> None:
    """Print LOG's messages as JSON lines, in log-time order.

    Each line is {"topic", "log_time_ns", "message"}. Bytes (a frame's PNG, a point cloud) are
    shown as their size unless --data. Pipe into jq to pick fields, e.g.
    `bslam cat run.mcap --topic /robot/movement | jq .message.index`.
    """
    import json

    from data_schemas.mcap.cat import log_documents
    from data_schemas.mcap.open import open_log
    from data_schemas.mcap.window import LogWindow

    with open_log(log) as opened:
        docs = log_documents(
            opened, topics or None, window=LogWindow(start, end), with_bytes=with_bytes
        )
        for doc in docs:
            click.echo(json.dumps(doc, separators=(",", ":")))
