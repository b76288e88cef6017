"""``bslam process``: logs in, maps out (derived log + summary JSON)."""

from __future__ import annotations

import logging
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

if TYPE_CHECKING:
    from replay.records import MethodConfig

PRIOR_CHOICES = ("impartial", "gaussian", "mixture")
#: --estimator choices, the default first (pipeline.estimators.ESTIMATORS; not imported here so
#: that `bslam --help` stays light)
ESTIMATOR_CHOICES = ("joint", "paper")

estimator_option = click.option(
    "--estimator",
    type=click.Choice(ESTIMATOR_CHOICES),
    default=ESTIMATOR_CHOICES[0],
    show_default=True,
    help="joint: every bearing in one factor graph (GTSAM), initialized by the paper's filter; "
    "paper: the paper's filter alone.",
)


def method_options(fn: click.decorators.FC) -> click.decorators.FC:
    """The estimator options shared by process, replay and demo."""
    for option in reversed(
        [
            estimator_option,
            click.option(
                "--turn-prior",
                "turn_prior_deg",
                type=click.FloatRange(0.0, min_open=True),
                default=None,
                metavar="DEG",
                help="Joint estimator: trust each commanded turn in place to this std "
                "(degrees) [default: turns free].",
            ),
            click.option(
                "--prior",
                type=click.Choice(PRIOR_CHOICES),
                default="impartial",
                show_default=True,
                help="Density of one bearing: the paper's impartial PDF or a baseline.",
            ),
            click.option(
                "--n-r",
                type=click.IntRange(2),
                default=50,
                show_default=True,
                help="Particles per landmark in FR.",
            ),
            click.option(
                "--n-l",
                type=click.IntRange(2),
                default=300,
                show_default=True,
                help="Particles per landmark in FL.",
            ),
            click.option(
                "--seed",
                type=int,
                default=0,
                show_default=True,
                help="Seed of the estimator's random generator.",
            ),
        ]
    ):
        fn = option(fn)
    return fn


class _WarningEcho(logging.Handler):
    """Echo each record to the current stderr as ``warning: <message>``."""

    def emit(self, record: logging.LogRecord) -> None:
        click.echo(f"warning: {record.getMessage()}", err=True)


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
def process(
    logs: tuple[str, ...],
    out: Path | None,
    summary: Path | None,
    estimator: str,
    turn_prior_deg: float | None,
    prior: str,
    n_r: int,
    n_l: int,
    seed: int,
    workers: int,
    scheduler: str | None,
) -> None:
    """Process LOGS (files, folders or globs) into maps.

    Each log goes through bearing extraction, initialization in FR, change of frame and fusion
    in FL (the paper's filter), and with the joint estimator (default) one factor graph over
    every bearing. With one log and neither --out nor --summary, the summary JSON goes to
    stdout, and each skipped movement is reported on stderr. Several logs run in parallel with
    one result line per log (skips are counted there); one failing log is reported and the
    others go on.
    """
    from replay.batch import expand_logs
    from replay.process import dumps, process_log, result_line
    from replay.records import MethodConfig

    method = MethodConfig(
        prior=prior,
        n_r=n_r,
        n_l=n_l,
        seed=seed,
        estimator=estimator,
        turn_prior_deg=turn_prior_deg,
    )
    paths = expand_logs(logs)
    if len(paths) == 1 and scheduler is None:
        with show_skips():
            doc = process_log(paths[0], method, out=out, summary=summary)
        if out is None and summary is None:
            click.echo(dumps(doc))
        else:
            click.echo(f"{paths[0]}: {result_line(doc)}")
        return
    _process_many(paths, out, summary, method, workers, scheduler)


def _process_many(
    paths: list[Path],
    out: Path | None,
    summary: Path | None,
    method: MethodConfig,
    workers: int,
    scheduler: str | None,
) -> None:
    """Many logs (or a Dask run): a pool, a progress bar and one result line per log."""
    from tqdm import tqdm  # the pool, the bar and Dask only when there are many logs

    from replay.batch import plan_jobs, process_job
    from replay.parallel import Outcome, run_tasks
    from replay.process import result_line

    jobs = plan_jobs(paths, out, summary, method)

    def report(outcome: Outcome[dict[str, Any]]) -> None:
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
