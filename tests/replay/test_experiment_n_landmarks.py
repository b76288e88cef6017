"""``bslam experiment sweep --param n_landmarks``: coded landmarks generated per value, scored."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner
from viewer import needs_experiments

from recorder.sim.scenario import builtin_scenario, scenario_from_dict
from replay.cli import cli
from replay.experiments.protocol import ProtocolError, apply_scenario_param


def test_n_landmarks_replaces_the_landmarks_by_coded_ones() -> None:
    base = builtin_scenario("paper").to_dict()
    doc = apply_scenario_param(base, "n_landmarks", 6.0)
    s = scenario_from_dict(doc)
    assert [lm.name for lm in s.landmarks] == [f"L{i}" for i in range(1, 7)]
    assert all(len(lm.bands) == 2 for lm in s.landmarks) and s.reference == ("L1", "L2")
    assert (s.arena.width_m, s.arena.height_m) == (1.05, 0.68)
    assert base["landmarks"][0]["color"] == "red"  # the base scenario is left as it was
    with pytest.raises(ProtocolError, match="whole number"):
        apply_scenario_param(base, "n_landmarks", 4.5)


@needs_experiments
def test_sweep_scores_every_groups_landmarks(tmp_path: Path) -> None:
    out = tmp_path / "sweep"
    args = ["experiment", "sweep", "--param", "n_landmarks", "--values", "4,6", "--runs", "1"]
    args += ["--movements", "3", "--priors", "impartial", "--workers", "1", "--quiet"]
    result = CliRunner().invoke(cli, [*args, "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "| 4 |" in result.output and "| 6 |" in result.output
    results = json.loads((out / "results.json").read_text())
    assert results["config"]["scored_landmarks"] == ["L3", "L4", "L5", "L6"]
    scenario = json.loads((out / "runs" / "n_landmarks_6" / "run_000.scenario.json").read_text())
    assert len(scenario["landmarks"]) == 6 and "bands" in scenario["landmarks"][5]
