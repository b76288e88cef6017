"""``bslam info LOG.mcap``: prints :func:`data_schemas.mcap.info.log_summary`'s report."""

from __future__ import annotations

import click


@click.command("info")
@click.argument("log", type=click.Path(dir_okay=False))
@click.option("--check", is_flag=True, help="Read every chunk and check its CRC.")
def info(log: str, check: bool) -> None:
    """Summarise a log: channels, counts, duration, metadata, attachments, damage.

    A finished, indexed log is summarised from its summary section (a few reads, whatever its
    size); with --check, and for any other log, every chunk is read and its CRC checked. An
    unfinished log (the recording was interrupted) or a corrupt one is summarised as far as it
    reads, then the command exits 1 and suggests `bslam recover`. A log still being recorded
    (its recorder holds a lock on it) is summarised as far as it is written, exit 0, with a
    pointer to `--follow`.
    """
    import shlex

    from data_schemas.errors import CorruptLogError, UnfinishedLogError, recover_hint
    from data_schemas.mcap.info import log_summary, summary_lines
    from data_schemas.mcap.read import corrupt_log_line, corruption, unfinished_line
    from data_schemas.outputs import being_written

    recording = being_written(log)  # the recorder's lock: before the scan reads the file
    s = log_summary(log, check=check)
    lines = summary_lines(s)
    if recording and s.state != "finished":
        lines[0] = f"{s.name}: being recorded (unfinished until the recorder ends)"
    for line in lines:
        click.echo(line)
    if recording and s.state != "finished":
        follow = shlex.join(["bslam", "process", "--follow", log])
        click.echo(f"{s.name} is being recorded: watch it grow with `{follow}`", err=True)
        return
    if s.state == "corrupt":
        raise CorruptLogError(corrupt_log_line(s.name, corruption(s.damage), recover_hint(s.name)))
    if s.state == "unfinished":
        raise UnfinishedLogError(unfinished_line(s.name, s.message_count, s.trailing_bytes))
