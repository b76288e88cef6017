"""A driving robot's log (bearings and odometry, no camera) through ``bslam process`` and
``bslam replay``: summary, derived log, Rerun recording, and the one-line errors."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import click
import numpy as np
import pytest
from click.testing import CliRunner
from importing import on, read_back
from test_rerun import _read

from pipeline.driving.simulate import DrivingSpec, arenas, simulate_drive
from replay.cli import cli
from replay.drive_sim import drive_messages, drive_session, simulate_drive_log
from replay.importers.source import ImportedLog, SourceFile
from replay.importers.write import import_log

KEYFRAME_M, KEYFRAME_DEG = 0.3, 20.0  # the driving estimator's defaults


@pytest.fixture(scope="module")
def drive_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("drive") / "square.mcap"
    simulate_drive_log(path, arena="square", duration_s=40.0, seed=5)
    return path


def _keyframes_by_hand(odometry: list[dict[str, Any]]) -> int:
    """Keyframes of the rule, counted along the odometry: path >= 0.3 m or turning >= 20 deg."""
    count, path, turn, last = 0, 0.0, 0.0, None
    for o in odometry:
        p = (o["x_m"], o["y_m"], o["theta_rad"])
        if last is None:
            count += 1
        else:
            path += math.dist(p[:2], last[:2])
            turn += abs(math.remainder(p[2] - last[2], 2 * math.pi))
            if path >= KEYFRAME_M or turn >= math.radians(KEYFRAME_DEG):
                count, path, turn = count + 1, 0.0, 0.0
        last = p
    return count


def _fl(p: tuple[float, float], l1: tuple[float, float], l2: tuple[float, float]) -> complex:
    """A point in FL (L1 -> 0, L2 -> 1), with complex numbers."""
    return (complex(*p) - complex(*l1)) / (complex(*l2) - complex(*l1))


def test_process_maps_a_driving_log(drive_log: Path, tmp_path: Path) -> None:
    summary, out = tmp_path / "s.json", tmp_path / "derived.mcap"
    result = CliRunner().invoke(
        cli, ["process", str(drive_log), "--summary", str(summary), "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    doc = json.loads(summary.read_text())
    assert doc["method"]["estimator"] == "driving"
    session, messages = read_back(drive_log)
    assert "camera" not in session
    keyframes = _keyframes_by_hand(on(messages, "/robot/odometry_pose"))
    assert len(doc["movements"]) == keyframes
    # the map against the truth the session keeps, sent to FL here (|L1 L2| = 3.04 m)
    truth = {t["name"]: (t["x_m"], t["y_m"]) for t in session["truth"]["landmarks"]}
    l1, l2 = truth["L1"], truth["L2"]
    unit_m = math.dist(l1, l2)
    assert set(doc["landmarks"]) == set(truth) - {"L1", "L2"}
    errors_m = [
        abs(complex(*est["mean"]) - _fl(truth[name], l1, l2)) * unit_m
        for name, est in doc["landmarks"].items()
    ]
    assert np.mean(errors_m) < 0.10 and max(errors_m) < 0.20, errors_m
    assert doc["mean_error_m"] == pytest.approx(np.mean(errors_m), abs=1e-6)
    assert doc["map_unit_m"] == pytest.approx(unit_m, rel=0.03)  # odometry gives the scale
    # the derived log: one estimate and one bearing set per keyframe
    _, derived = read_back(out)
    estimates = on(derived, "/pipeline/estimate")
    assert len(estimates) == keyframes
    assert {e["estimator"] for e in estimates} == {"driving"}
    assert len(on(derived, "/pipeline/bearings")) == keyframes


def test_replay_shows_rays_and_trajectory(drive_log: Path, tmp_path: Path) -> None:
    rrd = tmp_path / "drive.rrd"
    result = CliRunner().invoke(cli, ["replay", str(drive_log), "--save", str(rrd)])
    assert result.exit_code == 0, result.output
    rows = _read(rrd)
    for entity in ("/map/rays", "/map/trajectory", "/map/estimates", "/bearings/L3"):
        assert entity in rows, entity
    # a ray starts where it was measured: next to a keyframe of the trajectory (its window's
    # first bearing of the landmark: 0.2 s a sensor sample, 5 % missed, 0.25 m/s: within
    # 0.6 s, 15 cm, 0.05 FL, but for three misses in a row)
    strips = [s for r in rows["/map/rays"] for s in (r.get("LineStrips2D:strips") or [])]
    assert strips
    starts = np.array([np.asarray(s[0], float) for s in strips])
    path = [p for r in rows["/map/trajectory"] for p in (r.get("Points2D:positions") or [])]
    keyframes = np.array([np.asarray(p, float) for p in path])
    nearest = np.min(np.linalg.norm(starts[:, None, :] - keyframes[None, :, :], axis=2), axis=1)
    assert nearest.max() < 0.05


@dataclass(frozen=True)
class _Some:
    """A driving log with only some of its channels."""

    imported: ImportedLog

    @property
    def inputs(self) -> tuple[SourceFile, ...]:
        return ()

    def read(self) -> ImportedLog:
        return self.imported


def _partial(tmp_path: Path, topics: set[str]) -> Path:
    run = simulate_drive(arenas()["few"], DrivingSpec(duration_s=5.0), np.random.default_rng(0))
    messages = [m for m in drive_messages(run) if m.topic in topics]
    path = tmp_path / "partial.mcap"
    import_log(_Some(ImportedLog(drive_session(run, 2.0), messages, len(messages))), path)
    return path


@pytest.mark.parametrize(
    ("topics", "expected"),
    [
        ({"/sim/ground_truth"}, "neither frames (/camera/panorama) nor bearings"),
        ({"/sensor/bearings"}, "bearings without odometry (/robot/odometry_pose)"),
    ],
)
def test_log_without_what_to_map_is_one_line(
    tmp_path: Path, topics: set[str], expected: str
) -> None:
    log = _partial(tmp_path, topics)
    for command in ("process", "replay"):
        result = CliRunner().invoke(
            cli,
            [command, str(log), "--save", str(tmp_path / "x.rrd")]
            if command == "replay"
            else [command, str(log)],
        )
        assert result.exit_code == 1, result.output
        lines = result.output.strip().splitlines()
        assert lines[-1].startswith("Error: ") and expected in lines[-1], result.output


def test_paper_estimator_refuses_a_driving_log(drive_log: Path) -> None:
    result = CliRunner().invoke(cli, ["process", str(drive_log), "--estimator", "paper"])
    assert result.exit_code == 1
    assert "Error: " in result.output and "stop-and-go" in result.output


def test_help_states_the_driving_estimators_defaults() -> None:
    from pipeline.driving.keyframes import KEYFRAME_DISTANCE_M, KEYFRAME_TURN_RAD
    from pipeline.driving.odometry import ROT_STD_PER_RAD, TRANS_STD_PER_M

    want = {
        "keyframe_distance_m": KEYFRAME_DISTANCE_M,
        "keyframe_turn_deg": math.degrees(KEYFRAME_TURN_RAD),
        "odometry_std_per_m": TRANS_STD_PER_M,
        "odometry_heading_std_per_rad": ROT_STD_PER_RAD,
    }
    for command in ("process", "replay"):
        with click.Context(cli) as ctx:
            found = cli.get_command(ctx, command)  # type: ignore[attr-defined]
        assert found is not None
        params = {p.name: p for p in found.params}
        for name, value in want.items():
            assert f"[default: {value:g}]" in (params[name].help or ""), (command, name)


def test_keyframe_window_from_the_command_line(drive_log: Path, tmp_path: Path) -> None:
    """``--keyframe-window`` reaches the estimator: older keyframes leave the graph (the map
    moves off the one that keeps every keyframe) and the map still holds against the truth."""
    docs = {}
    for window in ("0", "5"):
        summary = tmp_path / f"s{window}.json"
        args = ["process", str(drive_log), "--keyframe-window", window, "--summary", str(summary)]
        result = CliRunner().invoke(cli, args)
        assert result.exit_code == 0, result.output
        docs[window] = json.loads(summary.read_text())
    assert docs["0"]["method"]["keyframe_window"] is None  # 0: every keyframe
    assert docs["5"]["method"]["keyframe_window"] == 5
    assert len(docs["5"]["movements"]) > 5 + docs["5"]["method"]["keyframe_window_stride"]
    means = {w: {n: e["mean"] for n, e in d["landmarks"].items()} for w, d in docs.items()}
    assert means["5"] != means["0"]
    session, _ = read_back(drive_log)
    truth = {t["name"]: (t["x_m"], t["y_m"]) for t in session["truth"]["landmarks"]}
    l1, l2 = truth["L1"], truth["L2"]
    errors_m = [
        abs(complex(*m) - _fl(truth[name], l1, l2)) * math.dist(l1, l2)
        for name, m in means["5"].items()
    ]
    assert np.mean(errors_m) < 0.10 and max(errors_m) < 0.20, errors_m


def test_keyframe_window_below_zero_is_a_usage_error(drive_log: Path) -> None:
    result = CliRunner().invoke(cli, ["process", str(drive_log), "--keyframe-window", "-1"])
    assert result.exit_code == 2
    assert "--keyframe-window" in result.output
