"""``bslam regress``: rerun the stored logs and report any estimate that moved."""

from __future__ import annotations

import logging
import sys
from pathlib import Path

import click

from replay.cli.process import ESTIMATOR_CHOICES

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
    type=click.FloatRange(0.0),
    default=None,
    help="Largest allowed move of a landmark mean, FL units [default: 1e-3].",
)
@click.option(
    "--estimator",
    type=click.Choice(ESTIMATOR_CHOICES),
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

    from replay.process import process_log, write_json
    from replay.regress import MEAN_TOL, compare, find_cases, load_expected

    logging.getLogger("bslam").setLevel(logging.ERROR)  # skipped movements are in the diff
    cases = find_cases(folder, update=update, estimator=estimator)
    regressions = 0
    for case in tqdm(cases, desc="regress", unit="log", file=sys.stderr):
        expected = load_expected(case) if case.expected.is_file() else None
        actual = process_log(case.log, case.method())
        if update:
            write_json(case.expected, actual)
            tqdm.write(f"{case.name}: wrote {case.expected.name}")
            continue
        assert expected is not None
        diffs = compare(expected, actual, mean_tol=MEAN_TOL if tolerance is None else tolerance)
        if diffs:
            regressions += 1
            tqdm.write(f"{case.name}: REGRESSION")
            for line in diffs:
                tqdm.write(f"  {line}")
        else:
            tqdm.write(f"{case.name}: ok")
    if regressions:
        raise click.ClickException(
            f"{regressions} of {len(cases)} logs regressed; if the change is intended, run "
            f"'bslam regress {folder} --update' and commit the expected files"
        )
