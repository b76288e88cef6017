"""`bslam experiment`: a tiny paper experiment end to end, and bad input (exit 1, one line)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from click.testing import CliRunner
from viewer import needs_experiments

from replay.cli import COMMANDS, cli
from replay.defaults import DISTANCE_PRIOR_REL
from replay.experiments.results import read_results
from replay.experiments.stats import movement_curve

pytestmark = needs_experiments  # the experiment command needs its extra

needs_simulate = pytest.mark.skipif(
    "simulate" not in COMMANDS, reason="`bslam simulate` (recorder branch) is not merged yet"
)


@pytest.mark.slow
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
    assert methods == {"impartial", "gaussian", "mixture", "joint", "batch_ls", "crb"}
    assert len([r for r in res.rows if r.method == "joint"]) == 3 * 4 * 2
    assert res.config["protocol"]["distance_prior"] == DISTANCE_PRIOR_REL
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
        (["--n-l-values", "50,abc"], "'--n-l-values': expected comma-separated integers"),
        (["--n-l-values", "50,1"], "particle counts must be at least 2"),
        (["--priors", "impartial,flat"], "'--priors': expected a comma-separated list of"),
        (["--runs", "0"], "'--runs': 0 is not in the range x>=1"),
        (["--movements", "-3"], "'--movements'"),
        (["--workers", "0"], "'--workers'"),
        (["--n-r", "1"], "'--n-r'"),
        (["--seed", "-1"], "'--seed': -1 is not in the range x>=0"),
        (["--frame-change", "fast"], "'fast' is not one of 'sampled', 'exact'"),
        (["--distance-prior", "-0.1"], "'--distance-prior': -0.1 is not in the range x>=0"),
        (["--distance-prior", "nan"], "'--distance-prior'"),
    ],
)
def test_paper_usage_error_is_exit_2_and_creates_nothing(
    tmp_path: Path, extra: list[str], message: str
) -> None:
    out = tmp_path / "o"
    code, output = run_cli(["experiment", "paper", "--out", str(out), *extra])
    assert code == 2, output
    lines = output.strip().splitlines()
    assert message in lines[0] and lines[0].startswith("Error: ")
    assert lines[1:] == ["Try 'cli experiment paper --help'."]
    assert not out.exists()


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--scenario", "no/such/scenario.json"], "no/such/scenario.json"),
        (["--scenario", "paper_omnii"], "paper_omnii"),
    ],
)
def test_paper_bad_scenario_is_one_line_exit_1_and_creates_nothing(
    tmp_path: Path, extra: list[str], message: str
) -> None:
    out = tmp_path / "o"
    code, output = run_cli(["experiment", "paper", "--out", str(out), *extra])
    assert code == 1, output
    assert message in output
    assert len(output.strip().splitlines()) == 1
    assert not out.exists()


def test_out_is_a_file_and_unknown_sweep_param(tmp_path: Path) -> None:
    f = tmp_path / "file"
    f.write_text("x")
    code, output = run_cli(["experiment", "paper", "--out", str(f)])
    assert code == 1 and "is a file" in output and len(output.strip().splitlines()) == 1
    code, output = run_cli(
        ["experiment", "sweep", "--out", str(tmp_path / "s"), "--param", "speed", "--values", "1"]
    )
    assert code == 2 and "'speed' is not one of 'bearing_noise_deg'" in output
    assert len(output.strip().splitlines()) == 2


@pytest.mark.parametrize(
    ("param", "values", "code", "message"),
    [
        ("n_l", "a,b", 2, "n_l takes integers of at least 2, got 'a'"),
        ("n_l", "50,1", 2, "n_l takes integers of at least 2, got '1'"),
        ("bearing_noise_deg", "1,nan", 2, "bearing_noise_deg takes finite numbers, got 'nan'"),
        ("frame_change", "sampled,fast", 2, "frame_change takes sampled or exact, got 'fast'"),
        (
            "vision_error_deg",
            "3,95",
            1,
            "scenario with vision_error_deg=95: field 'vision_error_deg': 95.0 is greater than",
        ),
        ("bearing_noise_deg", "-1", 1, "field 'camera.bearing_noise_deg': -1.0 is less than"),
        ("camera_model", "unwrapped,fisheye", 1, "'fisheye' is neither a scenario file"),
    ],
)
def test_sweep_bad_values_are_one_line_and_create_nothing(
    tmp_path: Path, param: str, values: str, code: int, message: str
) -> None:
    out = tmp_path / "s"
    args = ["experiment", "sweep", "--out", str(out), "--param", param, "--values", values]
    got, output = run_cli([*args, "--runs", "1", "--movements", "1", "--quiet"])
    assert got == code, output
    assert message in output.splitlines()[0]
    assert len(output.strip().splitlines()) == code  # usage errors add the --help hint
    assert not out.exists()


@needs_simulate
def test_tiny_sweep_end_to_end_is_quiet(tmp_path: Path) -> None:
    out = tmp_path / "sweep"
    args = [
        "experiment",
        "sweep",
        "--out",
        str(out),
        "--param",
        "n_l",
        "--values",
        "40,80",
        "--runs",
        "2",
        "--movements",
        "4",
        "--n-r",
        "30",
        "--priors",
        "impartial,mixture",
        "--workers",
        "1",
        "--quiet",
    ]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    # the summary table and one line: no simulator output, no skipped-movement warnings
    *table, last = result.output.strip().splitlines()
    assert last.startswith("4/4 runs ok")
    assert table[0].startswith("Mean error (cm) over runs after 3 / 4 movements")
    assert [line[:7] for line in table[2:] if not line.startswith("|-")] == [
        "| n_l |",
        "| 40 | ",
        "| 80 | ",
    ]
    res = read_results(out)
    assert sorted({r.group for r in res.runs}) == ["n_l=40", "n_l=80"]
    for value in (40, 80):
        rows = [r for r in res.rows if r.group == f"n_l={value}" and r.method == "impartial"]
        assert {r.n_l for r in rows} == {value}
        assert len(rows) == 2 * 4 * 2  # runs x movements x scored landmarks
        last = [r for r in rows if r.movement == 4]
        assert all(math.isfinite(r.error_cm) and 0 <= r.error_cm < 30 for r in last)
    assert {r.method for r in res.rows} == {"impartial", "mixture", "joint", "batch_ls", "crb"}
    assert (out / "sweep_n_l.png").stat().st_size > 0
    report = (out / "report.md").read_text()
    tables = report.split("## n_l=")[1:]
    assert [t.split("\n", 1)[0] for t in tables] == ["40", "80"]
    for table in tables:  # every value's table has numbers for the swept prior
        line = next(x for x in table.splitlines() if x.startswith("| impartial PDF |"))
        assert "nan" not in line and line.split("|")[2].strip()[0].isdigit(), line


@needs_simulate
def test_run_that_cannot_be_simulated_is_reported_in_one_line(tmp_path: Path) -> None:
    from replay.experiments.experiment import plan_runs, scenario_doc
    from replay.experiments.protocol import Protocol, apply_scenario_param
    from replay.experiments.run import run_one
    from replay.parallel import run_tasks

    doc = apply_scenario_param(scenario_doc("paper"), "movement_length_m", 2.0)  # arena: 1 m
    (task,) = plan_runs(Protocol(runs=1, movements=2), doc, tmp_path, "too_long")
    (outcome,) = run_tasks(run_one, [task], progress=False)
    assert not outcome.ok and outcome.error is not None
    assert outcome.error.startswith("move 0: no turn and distance in [1.6, 2.4] m")
    assert "trajectory.distance" in outcome.error and "\n" not in outcome.error


def test_names_agree_with_the_estimator() -> None:
    # replay.defaults spells the names out so that the CLI needs no numpy
    from typing import get_args

    from pipeline.estimators import ESTIMATORS
    from pipeline.fusion import PAPER_N_L, PAPER_N_R
    from pipeline.priors import PriorName
    from replay import defaults
    from replay.records import PRIORS as RECORD_PRIORS

    assert defaults.PRIORS == RECORD_PRIORS == get_args(PriorName)
    assert defaults.ESTIMATORS == ESTIMATORS
    assert (defaults.N_R, defaults.N_L) == (PAPER_N_R, PAPER_N_L) == (50, 300)  # the paper's


def test_distance_prior_default_is_shared() -> None:
    from replay.experiments.protocol import Protocol
    from replay.records import MethodConfig

    assert DISTANCE_PRIOR_REL is not None
    assert Protocol().distance_prior == MethodConfig().distance_prior == DISTANCE_PRIOR_REL
    # the summary says what made the map: the prior when the joint estimator used it
    assert MethodConfig().summary(0.05)["distance_prior"] == DISTANCE_PRIOR_REL
    assert "distance_prior" not in MethodConfig(distance_prior=None).summary(0.05)
    assert "distance_prior" not in MethodConfig(estimator="paper").summary(0.05)


def test_tiny_arenas_experiment_reports_the_goals(tmp_path: Path) -> None:
    out = tmp_path / "arenas"
    args = ["experiment", "arenas", "--out", str(out), "--runs", "2", "--movements", "6"]
    args += ["--seed", "10"]
    result = CliRunner().invoke(cli, [*args, "--workers", "1", "--quiet"])
    assert result.exit_code == 0, result.output
    goals = json.loads((out / "goals.json").read_text())
    assert goals["runs"] == 2 and goals["landmarks_scored"] >= 4
    assert set(goals["mean_error_cm"]) == {"joint", "batch_ls", "paper", "crb"}
    assert goals["missing_where_ls_places"] == 0
    scenarios = sorted((out / "runs" / "arenas").glob("*.scenario.json"))
    cams = [json.loads(p.read_text())["camera"]["model"] for p in scenarios]
    assert cams == ["unwrapped", "omni"]  # both camera models, alternated
    refs = [json.loads(p.read_text())["reference"] for p in scenarios]
    assert refs != [["L1", "L2"], ["L1", "L2"]]  # other reference pairs than the paper's
