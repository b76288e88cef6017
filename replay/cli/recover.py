"""``bslam recover BROKEN.mcap FIXED.mcap``: index every complete chunk of an unfinished log."""

from __future__ import annotations

import click


@click.command("recover")
@click.argument("broken", type=click.Path(dir_okay=False))
@click.argument("fixed", type=click.Path(dir_okay=False))
def recover(broken: str, fixed: str) -> None:
    """Rewrite every complete chunk of BROKEN (an interrupted log) into a new indexed FIXED."""
    from data_schemas.mcap.read import recover_log

    report = recover_log(broken, fixed)
    note = " (it was already finished)" if report.was_finished else ""
    click.echo(
        f"recovered {report.messages} messages ({report.channels} channels, {report.chunks} "
        f"chunks) from {broken}{note} into {fixed}; dropped {report.dropped_bytes} bytes of an "
        "incomplete chunk"
    )
