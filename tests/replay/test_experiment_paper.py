"""`bslam experiment`: a tiny paper experiment end to end, and bad input (exit 1, one line)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from click.testing import CliRunner

from replay.cli import COMMANDS, cli
from replay.experiments.results import read_results
from replay.experiments.stats import movement_curve

needs_simulate = pytest.mark.skipif(
    "simulate" not in COMMANDS, reason="`bslam simulate` (recorder branch) is not merged yet"
)


@needs_simulate
def test_tiny_paper_experiment_end_to_end(tmp_path: Path) -> None:
    out = tmp_path / "exp"
    args = [
        "experiment",
        "paper",
        "--out",
        str(out),
        "--runs",
        "3",
        "--movements",
        "4",
        "--n-l",
        "100",
        "--n-l-values",
        "50,100",
        "--workers",
        "1",
        "--seed",
        "5",
        "--quiet",
    ]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    assert "3/3 runs ok" in result.output
    res = read_results(out)
    assert [r.status for r in res.runs] == ["ok"] * 3
    # every run's log, its summary and its scenario are kept for replay
    for r in res.runs:
        log = Path(r.log)
        assert log.stat().st_size > 0
        summary = json.loads(log.with_suffix(".summary.json").read_text())
        assert len(summary["movements"]) == 4
    methods = {r.method for r in res.rows}
    assert methods == {"impartial", "gaussian", "mixture", "batch_ls", "crb"}
    # shape: 3 runs x 4 movements x 2 scored landmarks per method (n_l sweep: 3 movements)
    main = [r for r in res.rows if r.method == "impartial" and r.n_l == 100]
    assert len(main) == 3 * 4 * 2
    assert len([r for r in res.rows if r.method == "impartial" and r.n_l == 50]) == 3 * 3 * 2
    last = [r for r in res.rows if r.movement == 4 and r.method != "crb"]
    assert all(math.isfinite(r.error_cm) and 0 <= r.error_cm < 30 for r in last)
    # errors fall with movements on average
    for method in ("impartial", "mixture", "batch_ls"):
        n_l = 100 if method != "batch_ls" else 0
        curve = movement_curve(res.rows, method=method, n_l=n_l, landmarks=["L3", "L4"])
        assert curve[4].mean < curve[1].mean, method
    for name in (
        "fig1_priors.png",
        "fig7_movements.png",
        "fig8_n_l.png",
        "methods.png",
        "experiment.rrd",
        "errors.csv",
    ):
        assert (out / name).stat().st_size > 0, name
    report = (out / "report.md").read_text()
    assert "| impartial PDF |" in report and "![Fig. 7" in report


def run_cli(args: list[str]) -> tuple[int, str]:
    result = CliRunner().invoke(cli, args)
    return result.exit_code, result.output


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--n-l-values", "50,abc"], "--n-l-values: expected comma-separated integers"),
        (["--priors", "impartial,flat"], "unknown prior(s) ['flat']"),
        (["--runs", "0"], "runs and movements must be at least 1"),
        (["--frame-change", "fast"], "unknown frame change 'fast'"),
        (["--scenario", "no/such/scenario.json"], "no/such/scenario.json"),
    ],
)
def test_paper_bad_input_is_one_line_exit_1(tmp_path: Path, extra: list[str], message: str) -> None:
    code, output = run_cli(["experiment", "paper", "--out", str(tmp_path / "o"), *extra])
    assert code == 1, output
    assert message in output
    assert len(output.strip().splitlines()) == 1


def test_out_is_a_file_and_unknown_sweep_param(tmp_path: Path) -> None:
    f = tmp_path / "file"
    f.write_text("x")
    code, output = run_cli(["experiment", "paper", "--out", str(f)])
    assert code == 1 and "is a file" in output and len(output.strip().splitlines()) == 1
    code, output = run_cli(
        ["experiment", "sweep", "--out", str(tmp_path / "s"), "--param", "speed", "--values", "1"]
    )
    assert code == 1 and "unknown sweep parameter 'speed'" in output
    assert len(output.strip().splitlines()) == 1
