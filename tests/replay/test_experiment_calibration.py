"""``bslam experiment calibration``: per-family coverage with a bootstrap interval over runs, and
the command that writes it."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from data_schemas.errors import BslamError
from replay.cli import cli
from replay.experiments import calibration_experiment as ce
from replay.experiments.calibration import LandmarkScore

#: chi-square(2): P(d^2 <= q) = 1 - exp(-q / 2); the 80% and 99.99% radii, from that formula
Q80 = -2.0 * math.log(0.2)
Q9999 = -2.0 * math.log(1e-4)


def _run(d2: list[float], err: list[float], ls: list[float], seed: int = 0) -> list[LandmarkScore]:
    return [
        LandmarkScore("f", seed, f"L{i + 3}", e, b, d, 1.0)
        for i, (d, e, b) in enumerate(zip(d2, err, ls, strict=True))
    ]


def test_figures_of_a_hand_made_family() -> None:
    runs = [
        _run([1.0, 5.0], [1.0, 2.0], [2.0, 2.0]),
        _run([2.0], [3.0], [math.nan]),  # least squares did not place it: not in the ratio
        _run([10.0, 0.5, 20.0], [1.0, 1.0, 1.0], [1.0, 1.0, 1.0]),
    ]
    r = ce.family_coverage("f", runs, np.random.default_rng(0), failed=2)
    assert (r.runs, r.failed, r.regions) == (3, 2, 6)
    assert r.inside == pytest.approx(3 / 6)  # 1.0, 2.0 and 0.5 are below Q80 (3.22)
    assert r.median_d2 == pytest.approx(3.5)  # (2 + 5) / 2
    assert r.beyond_9999 == 1  # 20 > Q9999 (18.4)
    assert r.error_cm == pytest.approx(6.0 / 5.0) and r.batch_ls_cm == pytest.approx(7.0 / 5.0)
    assert r.ratio_to_ls == pytest.approx(6.0 / 7.0)
    # a resample's share lies between the smallest and largest run's (1/3 and 1)
    lo, hi = r.interval
    assert 1.0 / 3.0 <= lo <= r.inside <= hi <= 1.0
    assert "| f | 3 (2 failed) | 6 | 50.0% |" in ce.table_markdown([r])
    # the runs' own ratios: 3 / 4 and 3 / 3 (the second run has none); a resample's ratio of
    # sums lies between its runs' smallest and largest ratio
    assert r.median_run_ratio == pytest.approx((0.75 + 1.0) / 2)
    lo, hi = r.ratio_interval
    assert 0.75 <= lo <= r.ratio_to_ls <= hi <= 1.0
    assert "| 0.86 | 0.75-1.00 | 0.88 |" in ce.table_markdown([r])


def test_one_run_far_off_decides_the_ratio_of_means_not_its_median() -> None:
    # 39 runs at half least squares' error, one 50x least squares': the ratio of means is
    # (39 + 100) / 80; a resample leaves that run out with probability (39 / 40)^40 = 36%, so
    # the interval's low end is the other runs' 0.5
    runs = [_run([1.0], [1.0], [2.0], seed=i) for i in range(39)] + [_run([1.0], [100.0], [2.0])]
    r = ce.family_coverage("f", runs, np.random.default_rng(2))
    assert r.ratio_to_ls == pytest.approx(139.0 / 80.0)
    assert r.median_run_ratio == pytest.approx(0.5)
    lo, hi = r.ratio_interval
    assert lo == pytest.approx(0.5) and hi > 2.0 * r.ratio_to_ls


def test_interval_matches_the_binomial_for_independent_regions() -> None:
    # 400 runs of one region each, 320 inside: the 90% interval is about +-1.645 sqrt(.16/400)
    rng = np.random.default_rng(3)
    d2 = np.where(rng.permutation(400) < 320, 0.1, 9.0)
    runs = [_run([float(d)], [1.0], [1.0]) for d in d2]
    r = ce.family_coverage("f", runs, np.random.default_rng(1))
    half = 1.645 * math.sqrt(0.8 * 0.2 / 400)
    assert r.inside == pytest.approx(0.8)
    assert r.interval[0] == pytest.approx(0.8 - half, abs=0.008)
    assert r.interval[1] == pytest.approx(0.8 + half, abs=0.008)


def test_interval_is_over_runs_when_a_run_s_regions_go_together() -> None:
    # 40 runs of 10 regions, each run all inside or all outside: 40 draws, not 400
    runs = [_run([0.1 if i < 32 else 9.0] * 10, [1.0] * 10, [1.0] * 10) for i in range(40)]
    r = ce.family_coverage("f", runs, np.random.default_rng(1))
    half_runs = 1.645 * math.sqrt(0.8 * 0.2 / 40)
    half_regions = 1.645 * math.sqrt(0.8 * 0.2 / 400)
    width = r.interval[1] - r.interval[0]
    assert width == pytest.approx(2 * half_runs, rel=0.2)
    assert width > 2.5 * (2 * half_regions)


def test_a_family_without_scores_reads_as_such() -> None:
    r = ce.family_coverage("f", [], np.random.default_rng(0), failed=4)
    assert r.regions == 0 and math.isnan(r.inside) and r.failed == 4
    assert math.isnan(r.median_run_ratio) and all(map(math.isnan, r.ratio_interval))
    assert "| f | 0 (4 failed) | 0 | - |" in ce.table_markdown([r])


def test_command_writes_every_landmark_and_the_table(tmp_path: Path) -> None:
    out = tmp_path / "cal"
    args = ["experiment", "calibration", "--out", str(out), "--families", "paper,coded"]
    result = CliRunner().invoke(
        cli, [*args, "--runs", "2", "--seed", "5", "--workers", "1", "--quiet"]
    )
    assert result.exit_code == 0, result.output
    lines = [json.loads(x) for x in (out / "scores.jsonl").read_text().splitlines()]
    doc = json.loads((out / "calibration.json").read_text())
    assert doc["seeds"] == [5, 6] and doc["failed"] == []
    for fam in doc["families"]:
        mine = [x for x in lines if x["family"] == fam["family"]]
        assert {x["seed"] for x in mine} == {5, 6}
        # the paper's arena scores its two landmarks besides the reference pair, coded its six
        assert fam["regions"] == len(mine) == {"paper": 4, "coded": 12}[fam["family"]]
        inside = sum(x["d2"] <= Q80 for x in mine) / len(mine)
        assert fam["inside"] == pytest.approx(inside)
        assert all(x["inside"] == (x["d2"] <= Q80) for x in mine)
    assert "| paper | 2 | 4 |" in result.output and "| coded | 2 | 12 |" in result.output
    assert "4/4 runs ok" in result.output
    md = (out / "calibration.md").read_text()
    assert "| paper | 2 | 4 |" in md and "| coded | 2 | 12 |" in md


def test_unknown_family_is_one_line(tmp_path: Path) -> None:
    args = ["experiment", "calibration", "--out", str(tmp_path / "c"), "--families", "paper,moon"]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 2
    assert "moon" in result.output and "close_pairs" in result.output
    assert not (tmp_path / "c").exists()


def test_every_run_failing_is_one_line_and_exit_1(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def fail(family: str, seed: int) -> list[LandmarkScore]:
        raise BslamError(f"no log for {family} {seed}")

    monkeypatch.setattr(ce, "score_run", fail)
    args = ["experiment", "calibration", "--out", str(tmp_path / "c"), "--families", "paper"]
    result = CliRunner().invoke(cli, [*args, "--runs", "2", "--workers", "1", "--quiet"])
    assert result.exit_code == 1
    assert "no run succeeded: all 2 failed, e.g. paper seed 0: no log for paper 0" in result.output
