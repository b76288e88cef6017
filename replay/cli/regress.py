"""``bslam regress``: rerun the stored logs and report any estimate that moved."""

from __future__ import annotations

import logging
import shlex
import sys
from pathlib import Path

import click

from replay import defaults
from replay.cli.options import FiniteFloat

DEFAULT_DIR = Path("tests/data/regress")


@click.command("regress")
@click.argument("folder", required=False, type=click.Path(path_type=Path), default=DEFAULT_DIR)
@click.option(
    "--update",
    is_flag=True,
    help="Rewrite every NAME.expected.json from the current code (on purpose only).",
)
@click.option(
    "--tolerance",
    type=FiniteFloat(0.0),
    default=None,
    help="Largest allowed move of a landmark mean, FL units [default: 1e-3].",
)
@click.option(
    "--estimator",
    type=click.Choice(defaults.ESTIMATORS),
    default=None,
    help="Only the expected summaries this estimator made; with --update, create them where "
    "missing [default: all].",
)
def regress(folder: Path, update: bool, tolerance: float | None, estimator: str | None) -> None:
    """Reprocess every NAME.mcap in FOLDER and compare with its expected summaries.

    NAME.expected.json and NAME.<estimator>.expected.json (e.g. NAME.paper.expected.json) are
    each rerun with the estimator and settings they were made with. Exit 1 if a movement changed
    status or placement, a landmark appeared or disappeared, or a mean or covariance moved
    beyond the tolerance. FOLDER defaults to tests/data/regress.
    """
    from tqdm import tqdm

    from replay.regress import MEAN_TOL, CaseResult, find_cases, run_regression

    total = len(find_cases(folder, update=update, estimator=estimator))
    bar = tqdm(total=total, desc="regress", unit="log", file=sys.stderr, delay=0.5, disable=None)

    def report(result: CaseResult) -> None:
        bar.update()
        if result.status == "written":
            tqdm.write(f"{result.case.name}: wrote {result.case.expected.name}")
            return
        tqdm.write(f"{result.case.name}: {'ok' if result.status == 'ok' else 'REGRESSION'}")
        for line in result.diffs:
            tqdm.write(f"  {line}")

    logging.getLogger("bslam").setLevel(logging.ERROR)  # skipped movements are in the diff
    with bar:
        results = run_regression(
            folder,
            update=update,
            estimator=estimator,
            mean_tol=MEAN_TOL if tolerance is None else tolerance,
            on_case=report,
        )
    regressions = sum(r.status == "regression" for r in results)
    if regressions:
        again = shlex.join(["bslam", "regress", str(folder), "--update"])
        raise click.ClickException(
            f"{regressions} of {len(results)} logs regressed; if the change is intended, run "
            f"{again} and commit the expected files"
        )
