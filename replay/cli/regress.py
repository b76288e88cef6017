"""``bslam regress``: rerun the stored logs and report any estimate that moved."""

from __future__ import annotations

import logging
import sys
from pathlib import Path

import click

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
def regress(folder: Path, update: bool, tolerance: float | None) -> None:
    """Reprocess every NAME.mcap in FOLDER and compare with NAME.expected.json.

    Exit 1 if a movement changed status, a landmark appeared or disappeared, or a mean or
    covariance moved beyond the tolerance. FOLDER defaults to tests/data/regress.
    """
    from tqdm import tqdm

    from replay.process import process_log, write_json
    from replay.records import MethodConfig
    from replay.regress import MEAN_TOL, compare, find_cases, load_expected, method_of

    logging.getLogger("bslam").setLevel(logging.ERROR)  # skipped movements are in the diff
    cases = find_cases(folder, update=update)
    regressions = 0
    for case in tqdm(cases, desc="regress", unit="log", file=sys.stderr):
        expected = load_expected(case) if case.expected.is_file() else None
        method = MethodConfig() if expected is None else method_of(expected)
        actual = process_log(case.log, method)
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
