"""One log, one map: the Python API with its defaults and `bslam process` with its defaults
share one code path and one set of defaults (replay/defaults.py)."""

from __future__ import annotations

import json
from pathlib import Path

from click.testing import CliRunner

from replay.cli import cli
from replay.process import process_log
from replay.records import MethodConfig


def test_api_and_cli_make_the_same_map(small_log: Path, tmp_path: Path) -> None:
    api = process_log(small_log, MethodConfig()).to_json()
    result = CliRunner().invoke(
        cli, ["process", str(small_log), "--summary", str(tmp_path / "s.json")]
    )
    assert result.exit_code == 0, result.output
    by_cli = json.loads((tmp_path / "s.json").read_text())
    assert by_cli["method"] == api["method"]
    assert by_cli["movements"] == api["movements"]
    assert by_cli["landmarks"] == api["landmarks"]  # the same floats, not merely close
    # the distance prior (the default that once differed) changes this log's map: the
    # comparison above would see a default that differed
    free = process_log(small_log, MethodConfig(distance_prior=None)).to_json()
    assert free["landmarks"]["L3"]["mean"] != api["landmarks"]["L3"]["mean"]


def test_window_reaches_the_joint_estimator(small_log: Path, tmp_path: Path) -> None:
    from pipeline.joint.window import DEFAULT_WINDOW, MIN_WINDOW
    from replay import defaults
    from replay.regress import method_of

    assert defaults.JOINT_WINDOW == DEFAULT_WINDOW  # the CLI's default is the estimator's
    from pipeline.driving.estimator import DrivingOptions
    from pipeline.driving.lag import DEFAULT_KEYFRAME_WINDOW

    # and the driving estimator's window: the CLI's, the library's and the options' agree
    assert defaults.KEYFRAME_WINDOW == DEFAULT_KEYFRAME_WINDOW
    assert DrivingOptions().window_keyframes == DEFAULT_KEYFRAME_WINDOW
    # below the estimator's smallest window: its own one-line error, exit 1
    result = CliRunner().invoke(cli, ["process", str(small_log), "--window", str(MIN_WINDOW - 1)])
    assert result.exit_code == 1
    assert result.output.startswith("Error: ") and f"at least {MIN_WINDOW}" in result.output
    # 0 keeps every movement; the summary says so and regress reruns with it
    summary = tmp_path / "s.json"
    args = ["process", str(small_log), "--window", "0", "--summary", str(summary)]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    doc = json.loads(summary.read_text())
    assert doc["method"]["window"] == 0
    assert method_of(doc).window == 0
    assert "window" not in process_log(small_log, MethodConfig()).to_json()["method"]
