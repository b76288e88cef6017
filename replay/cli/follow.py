"""The ``--follow`` options of ``bslam process`` and ``bslam replay``, and how a follow ends."""

from __future__ import annotations

from typing import TYPE_CHECKING

import click

from data_schemas.mcap.read import IDLE_TIMEOUT_S

if TYPE_CHECKING:
    from data_schemas.mcap.follow import FollowedLog


def follow_options(fn: click.decorators.FC) -> click.decorators.FC:
    """Add ``--follow`` and ``--idle-timeout S``."""
    fn = click.option(
        "--idle-timeout",
        type=click.FloatRange(min=0, min_open=True),
        default=IDLE_TIMEOUT_S,
        show_default=True,
        metavar="S",
        help="With --follow: stop when LOG has not grown for S seconds (also the wait for it "
        "to appear).",
    )(fn)
    return click.option(
        "--follow",
        is_flag=True,
        help="LOG is still being written: process whole chunks as they arrive, stop when it "
        "is finished or idle.",
    )(fn)


def end_of_follow(log: FollowedLog) -> None:
    """Say why following stopped (stderr); exit 1 if the log never finished."""
    click.echo(log.end_line, err=True)
    if log.end != "finished":
        click.get_current_context().exit(1)
