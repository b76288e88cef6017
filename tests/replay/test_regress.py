"""Regression on the stored logs of tests/data/regress (both cameras, degenerate, occluded)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner

from replay.cli import cli
from replay.regress import compare

DATA = Path(__file__).resolve().parents[1] / "data" / "regress"


def test_stored_logs_have_not_regressed() -> None:
    # the default (joint) map and the paper filter's map, each from its own expected summary;
    # the paper's files predate the joint estimator: --estimator paper reproduces them
    result = CliRunner().invoke(cli, ["regress", str(DATA)])
    assert result.exit_code == 0, result.output
    for name in ("unwrapped", "omni", "degenerate", "occluded"):
        assert f"{name}.mcap: ok" in result.output
        assert f"{name}.mcap (paper): ok" in result.output
        paper = json.loads((DATA / f"{name}.paper.expected.json").read_text())
        assert "estimator" not in paper["method"]  # written before there was a choice
        joint = json.loads((DATA / f"{name}.expected.json").read_text())
        assert joint["method"]["estimator"] == "joint"


def test_stored_cases_cover_what_they_claim() -> None:
    omni = json.loads((DATA / "omni.expected.json").read_text())
    assert omni["camera_model"] == "omni"
    degenerate = json.loads((DATA / "degenerate.paper.expected.json").read_text())
    assert "parallel" in degenerate["movements"][0]["skipped_landmarks"]["L4"]
    occluded = json.loads((DATA / "occluded.expected.json").read_text())
    assert occluded["movements"][0]["bearings_deg"]["L5"][1] is None
    assert "L5" in occluded["landmarks"]
    # the omni log's second movement has a degenerate reference: the paper skips it, the
    # joint map places it by resection against the landmarks already mapped
    omni_paper = json.loads((DATA / "omni.paper.expected.json").read_text())
    assert omni_paper["movements"][1]["status"].startswith("skipped: reference landmark")
    assert omni["movements"][1]["placement"] == "resection"


def test_estimator_filter_and_update_create_only_that_estimators_file(tmp_path: Path) -> None:
    shutil.copy(DATA / "unwrapped.mcap", tmp_path / "unwrapped.mcap")
    shutil.copy(DATA / "unwrapped.paper.expected.json", tmp_path / "unwrapped.paper.expected.json")
    result = CliRunner().invoke(cli, ["regress", str(tmp_path), "--estimator", "joint"])
    assert result.exit_code == 1 and "no NAME.mcap with NAME.expected.json" in result.output
    update = ["regress", str(tmp_path), "--update", "--estimator", "joint"]
    assert CliRunner().invoke(cli, update).exit_code == 0
    assert sorted(p.name for p in tmp_path.glob("*.json")) == [
        "unwrapped.expected.json",
        "unwrapped.paper.expected.json",
    ]
    paper = (tmp_path / "unwrapped.paper.expected.json").read_text()
    assert paper == (DATA / "unwrapped.paper.expected.json").read_text()  # untouched
    result = CliRunner().invoke(cli, ["regress", str(tmp_path)])
    assert result.exit_code == 0
    assert "unwrapped.mcap: ok" in result.output and "unwrapped.mcap (paper): ok" in result.output


def test_moved_estimate_is_a_readable_regression(tmp_path: Path) -> None:
    for f in ("unwrapped.mcap", "unwrapped.expected.json"):
        shutil.copy(DATA / f, tmp_path / f)
    expected = tmp_path / "unwrapped.expected.json"
    doc = json.loads(expected.read_text())
    doc["landmarks"]["L4"]["mean"][0] += 0.01
    doc["movements"][1]["status"] = "skipped: made up"
    expected.write_text(json.dumps(doc))
    result = CliRunner().invoke(cli, ["regress", str(tmp_path)])
    assert result.exit_code == 1
    assert "unwrapped.mcap: REGRESSION" in result.output
    assert "final L4: mean moved by 0.01 (> 0.001)" in result.output
    assert "movement 1: status was 'skipped: made up', now 'ok'" in result.output
    assert "1 of 1 logs regressed" in result.output and "--update" in result.output
    # --update rewrites the expected file on purpose; then it passes again
    assert CliRunner().invoke(cli, ["regress", str(tmp_path), "--update"]).exit_code == 0
    assert CliRunner().invoke(cli, ["regress", str(tmp_path)]).exit_code == 0


def test_compare_lists_appearing_and_disappearing_landmarks() -> None:
    est = {"mean": [1.0, 2.0], "cov": [[1e-3, 0.0], [0.0, 1e-3]]}
    a = {
        "movements": [{"index": 0, "status": "ok", "landmarks": {"L3": est}}],
        "landmarks": {"L3": est},
    }
    b = {
        "movements": [{"index": 0, "status": "ok", "landmarks": {"L4": est}}],
        "landmarks": {"L4": est},
    }
    diffs = compare(a, b)
    assert any("L3: disappeared" in d for d in diffs)
    assert any("L4: new landmark" in d for d in diffs)
    assert compare(a, a) == []
    wider = {"mean": [1.0, 2.0], "cov": [[2e-3, 0.0], [0.0, 1e-3]]}
    c = {"movements": [], "landmarks": {"L3": wider}}
    assert any(
        "covariance changed by 100.0%" in d
        for d in compare({"movements": [], "landmarks": {"L3": est}}, c)
    )


def test_empty_folder_is_one_line(tmp_path: Path) -> None:
    result = CliRunner().invoke(cli, ["regress", str(tmp_path)])
    assert result.exit_code == 1
    assert "no NAME.mcap with NAME.expected.json" in result.output


def test_run_regression_returns_one_result_per_case(tmp_path: Path) -> None:
    from replay.regress import ToleranceError, run_regression

    for f in ("unwrapped.mcap", "unwrapped.expected.json", "omni.mcap", "omni.expected.json"):
        shutil.copy(DATA / f, tmp_path / f)
    seen: list[str] = []
    results = run_regression(tmp_path, on_case=lambda r: seen.append(r.case.name))
    assert [(r.case.name, r.status, r.diffs) for r in results] == [
        ("omni.mcap", "ok", []),
        ("unwrapped.mcap", "ok", []),
    ]
    assert seen == ["omni.mcap", "unwrapped.mcap"]  # reported as each case finishes
    expected = tmp_path / "omni.expected.json"
    doc = json.loads(expected.read_text())
    doc["landmarks"]["L3"]["mean"][1] -= 0.002
    expected.write_text(json.dumps(doc))
    omni, unwrapped = run_regression(tmp_path)
    assert omni.status == "regression" and unwrapped.status == "ok"
    assert omni.diffs == [d for d in omni.diffs if d.startswith("final L3: mean moved by 0.002")]
    assert len(omni.diffs) == 1
    assert run_regression(tmp_path, mean_tol=0.01)[0].status == "ok"  # within a looser bound
    written = run_regression(tmp_path, update=True)
    assert [r.status for r in written] == ["written", "written"]
    assert [r.status for r in run_regression(tmp_path)] == ["ok", "ok"]
    for bad in (float("nan"), float("inf"), -1.0):
        with pytest.raises(ToleranceError):
            run_regression(tmp_path, mean_tol=bad)
