"""``bslam recover BROKEN.mcap FIXED.mcap``: rewrite everything a damaged log still holds."""

from __future__ import annotations

import sys

import click


@click.command("recover")
@click.argument("broken", type=click.Path(dir_okay=False))
@click.argument("fixed", type=click.Path(dir_okay=False))
@click.option("--force", is_flag=True, help="Replace FIXED if it exists (never BROKEN).")
def recover(broken: str, fixed: str, force: bool) -> None:
    """Rewrite every message, metadata and attachment of BROKEN that checks out into FIXED.

    Works on interrupted recordings, cut or corrupt files and any valid MCAP. Exit 0 when
    nothing was lost, 3 when something was (each damaged part is listed), 1 when nothing could
    be read.
    """
    from data_schemas.mcap.recover import recover_log
    from replay.sinks.progress import progress_bar

    with progress_bar(desc="recovering", unit="msg") as bar:
        report = recover_log(broken, fixed, force=force, progress=lambda n: bar.update(n - bar.n))
    lines = report.lines(broken, fixed)
    click.echo(lines[0])
    for line in lines[1:]:
        click.echo(line, err=True)
    if report.exit_code:
        sys.exit(report.exit_code)
