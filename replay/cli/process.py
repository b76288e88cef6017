"""``bslam process``: logs in, maps out (derived log + summary JSON)."""

from __future__ import annotations

import logging
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

import click

from replay.cli.follow import end_of_follow, follow_options
from replay.cli.options import method_options, window_options

if TYPE_CHECKING:
    from data_schemas.mcap.window import Bound
    from replay.batch import LogJob
    from replay.records import MethodConfig
    from replay.sinks.summary import RunSummary


class _WarningEcho(logging.Handler):
    """Echo each record to the current stderr as ``warning: <message>``."""

    def emit(self, record: logging.LogRecord) -> None:
        from tqdm import tqdm  # above a progress bar, if one is drawn

        tqdm.write(f"warning: {record.getMessage()}", file=sys.stderr)


@contextmanager
def show_skips() -> Iterator[None]:
    """Print skipped movements (with the reason) to stderr while the block runs.

    The library logs them on the ``bslam`` loggers and prints nothing by itself; commands that
    handle one log turn this on, runs of many logs count skips in their result lines instead.
    """
    logger = logging.getLogger("bslam")
    handler = _WarningEcho(logging.WARNING)
    level, propagate = logger.level, logger.propagate
    logger.addHandler(handler)
    logger.setLevel(logging.WARNING)
    logger.propagate = False
    try:
        yield
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)
        logger.propagate = propagate


@click.command("process")
@click.argument("logs", nargs=-1, required=True)
@click.option(
    "--out",
    type=click.Path(path_type=Path),
    help="Derived log (a folder when there are many logs).",
)
@click.option(
    "--summary",
    type=click.Path(path_type=Path),
    help="Summary JSON (a folder when there are many logs).",
)
@method_options
@click.option(
    "--workers",
    type=click.IntRange(1),
    default=1,
    show_default=True,
    help="Local processes for many logs.",
)
@click.option(
    "--scheduler",
    metavar="ADDRESS",
    help="Run on a Dask cluster (e.g. tcp://host:8786) instead of local processes.",
)
@click.option("--force", is_flag=True, help="Replace existing outputs (never a log).")
@click.option(
    "--skip-corrupt",
    is_flag=True,
    help="Process a corrupt log without its damaged chunks (warned) instead of refusing it.",
)
@window_options
@follow_options
def process(
    logs: tuple[str, ...],
    out: Path | None,
    summary: Path | None,
    method: MethodConfig,
    workers: int,
    scheduler: str | None,
    force: bool,
    skip_corrupt: bool,
    start: Bound | None,
    end: Bound | None,
    follow: bool,
    idle_timeout: float,
) -> None:
    """Process LOGS (files, folders or globs) into maps.

    Each log goes through bearing extraction, initialization in FR, change of frame and fusion
    in FL (the paper's filter), and with the joint estimator (default) one factor graph over
    every bearing. With one log and neither --out nor --summary, the summary JSON goes to
    stdout, and each skipped movement is reported on stderr. Several logs run in parallel with
    one result line per log (skips are counted there); one failing log is reported and the
    others go on.

    With --follow, LOG (one file) is still being written: each movement is processed once its
    whole chunk is on disk, a compact view of the map is updated in place on stderr, and the
    command ends when LOG is finished (exit 0) or idle for --idle-timeout seconds (exit 1).

    --from and --to keep a part of each log: seconds from its start ('10s') or movements
    ('--from m2 --to m4': movements 2 to 4 whole).
    """
    from data_schemas.mcap.window import LogWindow
    from replay.batch import expand_logs, plan_jobs
    from replay.process import dumps, process_log, result_line
    from replay.sinks.progress import ProgressSink

    window = LogWindow(start, end)
    if follow and window:
        raise click.UsageError("--from/--to take a finished log, not --follow")
    if follow:
        _process_followed(logs, out, summary, method, idle_timeout, scheduler, force)
        return
    paths = expand_logs(logs)
    if len(paths) == 1 and scheduler is None:
        with show_skips():
            doc = process_log(
                paths[0],
                method,
                out=out,
                summary=summary,
                force=force,
                skip_corrupt=skip_corrupt,
                window=window,
                extra_sinks=(ProgressSink.for_log(paths[0], window),),
            )
        if out is None and summary is None:
            click.echo(dumps(doc.to_json()))
        else:
            click.echo(f"{paths[0]}: {result_line(doc)}")
        return
    jobs = plan_jobs(
        paths, out, summary, method, force=force, skip_corrupt=skip_corrupt, window=window
    )
    _process_many(jobs, workers, scheduler)


def _process_followed(
    logs: tuple[str, ...],
    out: Path | None,
    summary: Path | None,
    method: MethodConfig,
    idle_timeout: float,
    scheduler: str | None,
    force: bool,
) -> None:
    """One log followed while it is written, with the terminal view on stderr."""
    from data_schemas.mcap.open import open_log
    from replay.process import dumps, process_log, result_line
    from replay.sinks.terminal import TerminalView

    if len(logs) != 1 or scheduler is not None:
        raise click.UsageError("--follow takes one LOG file (and no --scheduler)")
    with open_log(logs[0], follow=True, idle_timeout_s=idle_timeout) as log:
        doc = process_log(
            log, method, out=out, summary=summary, extra_sinks=(TerminalView(),), force=force
        )
    if out is None and summary is None:
        click.echo(dumps(doc.to_json()))
    else:
        click.echo(f"{logs[0]}: {result_line(doc)}")
    end_of_follow(log)


def _process_many(jobs: list[LogJob], workers: int, scheduler: str | None) -> None:
    """Many logs (or a Dask run): a pool, a progress bar and one result line per log."""
    from tqdm import tqdm  # the pool, the bar and Dask only when there are many logs

    from replay.batch import process_job
    from replay.parallel import Outcome, run_tasks
    from replay.process import result_line

    def report(outcome: Outcome[RunSummary]) -> None:
        log = jobs[outcome.index].log
        if outcome.value is not None:
            tqdm.write(f"{log}: {result_line(outcome.value)}", file=sys.stdout)
        else:
            tqdm.write(f"{log}: FAILED: {outcome.error}", file=sys.stderr)

    outcomes = run_tasks(
        process_job,
        jobs,
        workers=workers,
        scheduler=scheduler,
        desc="logs",
        unit="log",
        on_outcome=report,
    )
    failed = sum(1 for o in outcomes if not o.ok)
    if failed:
        raise click.ClickException(f"{failed} of {len(jobs)} logs failed (see above)")
