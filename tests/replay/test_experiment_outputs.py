"""Results file, statistics, figures, .rrd and report from a small synthetic results set."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from replay.experiments.protocol import Protocol
from replay.experiments.report import method_table, n_l_flatness, write_report
from replay.experiments.results import (
    ErrorRow,
    Results,
    ResultsError,
    RunRecord,
    read_results,
    write_results,
)
from replay.experiments.rrd import write_rrd
from replay.experiments.scoring import inside_region
from replay.experiments.stats import (
    band,
    calibration,
    movement_curve,
    paired_difference,
    paired_ratio,
    per_run,
    select,
)

METHODS = ["impartial", "gaussian", "mixture", "batch_ls", "crb"]
SCALE = {"impartial": 1.0, "gaussian": 1.5, "mixture": 1.05, "batch_ls": 0.7, "crb": 0.5}


def synthetic(runs: int = 12, movements: int = 5) -> Results:
    rng = np.random.default_rng(3)
    proto = Protocol(runs=runs, movements=movements, n_l_values=(50, 300), n_l_movements=3)
    cfg = {
        "protocol": proto.to_dict(),
        "scored_landmarks": ["L3", "L4"],
        "methods": METHODS,
        "scenario": {"vision_error_deg": 3.0},
        "geometry": {
            "arena_cm": [105.0, 68.0],
            "baseline_cm": 30.0,
            "landmarks_cm": {"L1": [37.5, 55.0], "L2": [67.5, 55.0]},
            "camera": "unwrapped 255x176",
            "bearing_noise_deg": 1.0,
            "vision_error_deg": 3.0,
            "movement_length": "10-25 cm",
        },
    }
    rows = []
    for run in range(runs):
        for method in METHODS:
            n_ls = [0] if method in ("batch_ls", "crb") else [300]
            if method == "impartial":
                n_ls = [50, 300]
            for n_l in n_ls:
                last = movements if n_l == 300 or n_l == 0 else 3
                for m in range(1, last + 1):
                    for lm in ("L3", "L4"):
                        e = SCALE[method] * 3.0 / math.sqrt(m) * rng.lognormal(0.0, 0.3)
                        inside = None if method in ("batch_ls", "crb") else bool(rng.random() < 0.8)
                        rows.append(ErrorRow("paper", run, method, n_l, m, lm, e / 30, e, inside))
    runs_rec = [RunRecord("paper", r, r, f"runs/run_{r:03d}.mcap", "ok", 1.0) for r in range(runs)]
    runs_rec.append(RunRecord("paper", runs, runs, "runs/x.mcap", "failed: boom", 0.1))
    info = {"command": "bslam experiment paper --out X", "elapsed_s": 12.0, "workers": 2}
    return Results("paper", cfg, runs_rec, rows, info)


def test_results_roundtrip_with_nan(tmp_path: Path) -> None:
    res = synthetic(runs=3, movements=3)
    res.rows.append(ErrorRow("paper", 0, "gaussian", 300, 1, "L3", math.nan, math.nan, None))
    path = write_results(res, tmp_path)
    back = read_results(tmp_path)
    assert path.name == "results.json"
    assert back.config == res.config and back.runs == res.runs
    assert len(back.rows) == len(res.rows)
    assert math.isnan(back.rows[-1].error_cm)
    assert back.rows[0] == res.rows[0]
    assert (tmp_path / "errors.csv").read_text().count("\n") == len(res.rows) + 1


def test_read_results_errors(tmp_path: Path) -> None:
    with pytest.raises(ResultsError, match="no results file"):
        read_results(tmp_path)
    (tmp_path / "results.json").write_text("{not json")
    with pytest.raises(ResultsError, match="not a readable"):
        read_results(tmp_path)
    (tmp_path / "results.json").write_text('{"experiment": "x"}')
    with pytest.raises(ResultsError, match="malformed"):
        read_results(tmp_path)


def test_band_and_paired_difference() -> None:
    b = band(list(range(11)))
    assert (b.mean, b.lo, b.hi, b.n) == pytest.approx((5.0, 1.0, 9.0, 11))
    runs = {i: float(i) for i in range(20)}
    shifted = {i: float(i) + 1.0 + 0.01 * (i % 3) for i in range(20)}
    d = paired_difference(shifted, runs)
    assert d.mean == pytest.approx(1.0, abs=0.02) and d.p_value < 1e-6 and d.n == 20
    same = paired_difference(runs, runs)
    assert same.mean == 0.0 and same.p_value == 1.0


def test_ratio_to_batch_ls_on_shared_runs() -> None:
    assert paired_ratio({0: 2.0, 1: 4.0}, {0: 1.0, 1: 2.0, 2: 100.0}) == pytest.approx(2.0)
    assert math.isnan(paired_ratio({0: 1.0}, {1: 1.0}))
    # run 0 has no impartial estimate after 3 movements and a large least-squares error: it
    # must not enter the least-squares side of the impartial ratio
    res = synthetic()
    res.rows = [
        r if r.method != "batch_ls" or r.run != 0 else replace(r, error_cm=50.0)
        for r in res.rows
        if not (r.method == "impartial" and r.run == 0 and r.movement == 3)
    ]
    row = next(r for r in method_table(res) if r.method == "impartial")
    values = {
        m: per_run(select(res.rows, method=m, n_l=n, movement=3, landmarks=["L3", "L4"]))
        for m, n in (("impartial", 300), ("batch_ls", 0))
    }
    shared = [r for r in values["batch_ls"] if r in values["impartial"]]
    expected = np.mean([values["impartial"][r] for r in shared]) / np.mean(
        [values["batch_ls"][r] for r in shared]
    )
    assert 0 not in values["impartial"] and len(shared) == 11
    assert row.ratio_to_ls_early == pytest.approx(expected)
    assert row.ratio_to_ls_early > row.early.mean / np.mean(list(values["batch_ls"].values()))


def test_inside_region_matches_chi2() -> None:
    cov = np.diag([1.0, 4.0])
    # the 80% ellipse has Mahalanobis radius sqrt(3.219) = 1.794
    assert inside_region([0, 0], cov, [1.79, 0.0])
    assert not inside_region([0, 0], cov, [1.80, 0.0])
    assert inside_region([0, 0], cov, [0.0, 3.58])
    assert inside_region([0, 0], np.zeros((2, 2)), [0, 0]) is None


def test_curves_table_and_calibration() -> None:
    res = synthetic()
    curve = movement_curve(res.rows, method="impartial", n_l=300, landmarks=["L3", "L4"])
    assert sorted(curve) == [1, 2, 3, 4, 5]
    assert curve[5].mean < curve[1].mean
    assert all(b.lo <= b.mean <= b.hi and b.n == 12 for b in curve.values())
    table = {row.method: row for row in method_table(res)}
    assert set(table) == set(METHODS)
    assert table["gaussian"].early.mean > table["impartial"].early.mean
    assert table["batch_ls"].ratio_to_ls_final == pytest.approx(1.0)
    assert table["gaussian"].vs_impartial is not None and table["gaussian"].vs_impartial.mean > 0
    share, n = calibration(r for r in res.rows if r.method == "impartial" and r.n_l == 300)
    assert n == 12 * 5 * 2 and 0.65 < share < 0.95
    bands, spread = n_l_flatness(res)
    assert sorted(bands) == [50, 300] and 0.0 <= spread < 0.5


def test_figures_rrd_and_report(tmp_path: Path) -> None:
    import rerun as rr

    from replay.experiments import plots

    res = synthetic()
    figs = {
        "Fig. 7": plots.fig7_movements(res, tmp_path / "fig7.png").name,
        "Fig. 8": plots.fig8_n_l(res, tmp_path / "fig8.png").name,
        "Methods": plots.comparison(res, tmp_path / "methods.png").name,
    }
    for name in figs.values():
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    report = write_report(res, tmp_path, figs).read_text()
    assert "| impartial PDF |" in report and "about 2 cm" in report
    assert "![Fig. 7](fig7.png)" in report
    assert "failed: boom" in report
    write_rrd(res, tmp_path / "experiment.rrd")
    chunks = list(rr.chunk.RrdReader(tmp_path / "experiment.rrd").stream())
    entities = {c.entity_path for c in chunks}
    expected_entities = {"/fig7/L3/mean", "/fig8/mean", "/comparison/crb", "/calibration/impartial"}
    assert expected_entities | {"/fig1/range/impartial"} <= entities
    expected = movement_curve(res.rows, method="impartial", n_l=300, landmarks=["L3"])
    got: dict[int, float] = {}
    for c in chunks:
        if c.entity_path == "/fig7/L3/mean" and not c.is_static:
            batch = c.to_record_batch()
            cols = (batch["movement"].to_pylist(), batch["Scalars:scalars"].to_pylist())
            for m, v in zip(*cols, strict=True):
                got[m] = v[0]
    assert got == pytest.approx({m: b.mean for m, b in expected.items()})
