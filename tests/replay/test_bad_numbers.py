"""Impossible numbers, files and targets through the CLI: one line, exit 1 (usage errors: the
line and a hint to --help, exit 2); nothing is written before the input is checked."""

from __future__ import annotations

import copy
import json
import socket
import sys
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner
from logfactory import session_doc
from viewer import needs_experiments, needs_viewer

from data_schemas.mcap.writer import LogWriter
from recorder.clock import VirtualClock
from recorder.timebase import EpochClock
from replay.cli import cli

PAPER = json.loads(
    (Path(__file__).resolve().parents[2] / "recorder/sim/scenarios/paper.json").read_text()
)


def invoke(args: list[str]) -> tuple[int, list[str]]:
    result = CliRunner().invoke(cli, args)
    assert "Traceback" not in result.output
    return result.exit_code, [line for line in result.output.splitlines() if line.strip()]


def scenario(**changes: Any) -> dict[str, Any]:
    """The paper's scenario with ``changes`` applied ("a.b.c" keys, list indices as ints)."""
    doc = copy.deepcopy(PAPER)
    for path, value in changes.items():
        *parents, last = path.split("__")
        node: Any = doc
        for key in parents:
            node = node[int(key)] if key.isdigit() else node[key]
        node[int(last) if last.isdigit() else last] = value
    return doc


NAN, INF = float("nan"), float("inf")

BAD_SCENARIOS = {
    "negative seed": (
        scenario(trajectory__seed=-1),
        "field 'trajectory.seed': -1 is less than the minimum of 0",
    ),
    "infinite noise": (
        scenario(camera__bearing_noise_deg=INF),
        "field 'camera.bearing_noise_deg': must be a finite number, got inf",
    ),
    "nan noise": (
        scenario(camera__pixel_noise=NAN),
        "field 'camera.pixel_noise': must be a finite number, got nan",
    ),
    "nan arena": (scenario(arena__width=NAN), "field 'arena.width': must be a finite number"),
    "nan landmark": (
        scenario(landmarks__2__x=NAN),
        "field 'landmarks.2.x': must be a finite number",
    ),
    "infinite turn": (
        scenario(trajectory__start=[0.5, 0.3, INF]),
        "field 'trajectory.start.2': must be a finite number, got inf",
    ),
    "infinite distance": (
        scenario(trajectory__distance=[0.1, INF]),
        "field 'trajectory.distance.1': must be a finite number",
    ),
    "camera too large": (
        scenario(camera__width=2_000_000, camera__height=2_000_000),
        "field 'camera.width': 2000000 is greater than the maximum of 4096",
    ),
    "eps of 90 deg": (
        scenario(vision_error_deg=90),
        "field 'vision_error_deg': 90 is greater than or equal to the maximum of 90",
    ),
    "overlapping landmarks": (
        scenario(landmarks__3__x=0.2, landmarks__3__y=0.205),
        "landmark L4 at (0.2, 0.205) m overlaps landmark L3 at (0.2, 0.2) m",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_SCENARIOS))
def test_bad_scenario_is_one_line_and_writes_nothing(tmp_path: Path, case: str) -> None:
    doc, message = BAD_SCENARIOS[case]
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(doc))  # NaN and Infinity as Python's json writes them
    out = tmp_path / "sim.mcap"
    code, lines = invoke(["simulate", "--scenario", str(path), "--out", str(out)])
    assert code == 1, lines
    assert len(lines) == 1 and lines[0].startswith("Error: scenario bad.json: ")
    assert message in lines[0]
    assert not out.exists()


@pytest.mark.parametrize(
    ("args", "option", "message"),
    [
        (["--seed", "-1"], "--seed", "-1 is not in the range x>=0"),
        (["--rate", "inf"], "--rate", "'inf' is not a finite number"),
        (["--rate", "nan"], "--rate", "'nan' is not a finite number"),
        (["--turn-noise", "nan"], "--turn-noise", "'nan' is not a finite number"),
        (["--distance-noise", "inf"], "--distance-noise", "'inf' is not a finite number"),
        (["--turn-noise", "-0.1"], "--turn-noise", "-0.1 is not in the range x>=0"),
    ],
)
def test_simulate_bad_number_is_a_usage_error(
    tmp_path: Path, args: list[str], option: str, message: str
) -> None:
    out = tmp_path / "sim.mcap"
    code, lines = invoke(["simulate", "--scenario", "paper", "--out", str(out), *args])
    assert code == 2
    assert lines[0].startswith(f"Error: Invalid value for '{option}': {message}")
    assert lines[1:] == ["Try 'cli simulate --help'."]
    assert not out.exists()


@pytest.mark.parametrize("command", ["process", "replay", "demo"])
def test_negative_seed_is_a_usage_error_everywhere(
    tmp_path: Path, small_log: Path, command: str
) -> None:
    args = {"process": [str(small_log)], "replay": [str(small_log)], "demo": []}[command]
    code, lines = invoke([command, *args, "--seed", "-3"])
    assert code == 2
    assert lines[0] == "Error: Invalid value for '--seed': -3 is not in the range x>=0."
    assert len(lines) == 2


def _record_files(tmp_path: Path, calibration: Any, landmarks: Any) -> list[str]:
    (tmp_path / "cal.json").write_text(json.dumps(calibration))
    (tmp_path / "lm.json").write_text(json.dumps(landmarks))
    return [
        "record",
        "--port",
        str(tmp_path / "no-such-port"),
        "--camera",
        str(tmp_path / "no-such-video.avi"),
        "--out",
        str(tmp_path / "rec.mcap"),
        "--calibration",
        str(tmp_path / "cal.json"),
        "--landmarks",
        str(tmp_path / "lm.json"),
    ]


GOOD_CAL = {"model": "unwrapped", "width": 255, "height": 176}
GOOD_LM = {
    "landmarks": [{"name": "L1", "color": "red"}, {"name": "L2", "color": "green"}],
    "reference": ["L1", "L2"],
    "vision_error_deg": 3,
}


@pytest.mark.parametrize(
    ("calibration", "landmarks", "message"),
    [
        (
            {"model": "omni", "width": 100, "r_min": 10, "r_max": 40},
            GOOD_LM,
            "cal.json: field 'height': is missing",
        ),
        (
            {"model": "fisheye", "width": 100, "height": 100},
            GOOD_LM,
            "field 'model': 'fisheye' is not one of ['unwrapped', 'omni', 'pinhole']",
        ),
        (
            {"model": "omni", "width": 100, "height": 100, "cx": 500, "cy": 50},
            GOOD_LM,
            "field 'r_min': is missing",
        ),
        (
            {
                "model": "omni",
                "width": 100,
                "height": 100,
                "cx": 500,
                "cy": 50,
                "r_min": 5,
                "r_max": 40,
            },
            GOOD_LM,
            "omni calibration centre (500, 50) is outside the 100x100 image",
        ),
        (
            {"model": "omni", "width": 100, "height": 100, "r_min": 80, "r_max": 90},
            GOOD_LM,
            "omni calibration ring r_min=80 px lies outside the 100x100 image",
        ),
        (
            GOOD_CAL,
            {**GOOD_LM, "vision_error_deg": 120},
            "field 'vision_error_deg': 120 is greater than or equal to the maximum of 90",
        ),
        (
            GOOD_CAL,
            {**GOOD_LM, "vision_error_deg": NAN},
            "field 'vision_error_deg': must be a finite number, got nan",
        ),
    ],
)
def test_record_bad_file_names_the_field(
    tmp_path: Path, calibration: Any, landmarks: Any, message: str
) -> None:
    code, lines = invoke(_record_files(tmp_path, calibration, landmarks))
    assert code == 1, lines
    assert len(lines) == 1 and message in lines[0], lines
    assert not (tmp_path / "rec.mcap").exists()


@pytest.mark.parametrize(
    ("args", "option"),
    [
        (["--seed", "-1"], "--seed"),
        (["--turn-deg", "nan"], "--turn-deg"),
        (["--wheel-base", "inf"], "--wheel-base"),
        (["--mm-per-pulse", "0"], "--mm-per-pulse"),
        (["--distance", "0.1,inf"], "--distance"),
        (["--distance", "nan"], "--distance"),
        (["--baud", "0"], "--baud"),
    ],
)
def test_record_bad_number_is_a_usage_error(tmp_path: Path, args: list[str], option: str) -> None:
    code, lines = invoke([*_record_files(tmp_path, GOOD_CAL, GOOD_LM), *args])
    assert code == 2, lines
    assert lines[0].startswith(f"Error: Invalid value for '{option}'") and len(lines) == 2


def _log_with(path: Path, movement: dict[str, Any], monkeypatch: pytest.MonkeyPatch) -> Path:
    """A log whose first /robot/movement message is ``movement`` (the writer's check off)."""
    monkeypatch.setattr("data_schemas.mcap.writer.validate", lambda *a, **k: None)
    epoch = EpochClock(VirtualClock())
    with LogWriter(path, session_doc(), clock=epoch, fsync=False) as writer:
        writer.write("/robot/movement", movement)
    monkeypatch.undo()
    return path


STAMP = {"sec": 1_700_000_000, "nsec": 0}
MOVEMENT = {
    "timestamp": STAMP,
    "index": 0,
    "phase": "start",
    "keyframe_timestamp": STAMP,
    "turn_rad": 0.0,
    "distance_m": 0.1,
}


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"phase": None}, "field 'phase' is missing"),
        ({"index": "0"}, "field 'index' should be an integer, got str"),
        ({"phase": "middle"}, "field 'phase' should be one of ['start', 'end'], got 'middle'"),
        ({"keyframe_timestamp": {"sec": 1}}, "field 'keyframe_timestamp.nsec' is missing"),
    ],
)
@pytest.mark.parametrize("command", ["process", pytest.param("replay", marks=needs_viewer)])
def test_message_not_matching_its_schema_names_topic_time_and_field(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    change: dict[str, Any],
    message: str,
    command: str,
) -> None:
    movement = {k: v for k, v in {**MOVEMENT, **change}.items() if v is not None}
    log = _log_with(tmp_path / "odd.mcap", movement, monkeypatch)
    args = [command, str(log)] + (
        ["--save", str(tmp_path / "o.rrd")] if command == "replay" else []
    )
    code, lines = invoke(args)
    assert code == 1, lines
    assert len(lines) == 1
    assert lines[0].startswith("Error: /robot/movement at log time ")
    assert message in lines[0] and "bslam.Movement" in lines[0]


def test_regress_tolerance_nan_is_a_usage_error(tmp_path: Path) -> None:
    code, lines = invoke(["regress", str(tmp_path), "--tolerance", "nan"])
    assert code == 2 and "'nan' is not a finite number" in lines[0]


def test_bad_expected_file_is_one_line(tmp_path: Path, small_log: Path) -> None:
    (tmp_path / "a.mcap").write_bytes(small_log.read_bytes())
    expected = tmp_path / "a.expected.json"
    assert invoke(["regress", str(tmp_path), "--update"])[0] == 0
    doc = json.loads(expected.read_text())
    for damage, message in (
        (lambda d: d.pop("method"), "key 'method' is missing"),
        (lambda d: d["landmarks"].update(L3={"mean": [0.1]}), "key landmarks.L3.mean is not"),
        (lambda d: d["movements"][0].pop("status"), "key 'movements[0].status' is missing"),
        (lambda d: d.update(landmarks=[]), "key 'landmarks' is not an object"),
    ):
        bad = copy.deepcopy(doc)
        damage(bad)
        expected.write_text(json.dumps(bad))
        code, lines = invoke(["regress", str(tmp_path)])
        assert code == 1 and len(lines) == 1, lines
        assert message in lines[0] and "--update" in lines[0]
    expected.write_text("{not json")
    code, lines = invoke(["regress", str(tmp_path)])
    assert code == 1 and "cannot read the expected summary" in lines[0]


def test_regression_catches_a_nan_mean(tmp_path: Path, small_log: Path) -> None:
    """A NaN compares false with any tolerance: it must still count as a move."""
    from replay.regress import compare

    est = {"mean": [0.5, 0.5], "cov": [[1e-4, 0.0], [0.0, 1e-4]]}
    doc = {"movements": [], "landmarks": {"L3": est}}
    moved = {"movements": [], "landmarks": {"L3": {**est, "mean": [NAN, 0.5]}}}
    assert compare(doc, doc) == []
    assert any("L3: mean moved by nan" in d for d in compare(doc, moved))


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
    return port


@needs_viewer
def test_replay_connect_to_nothing_is_exit_1(small_log: Path) -> None:
    url = f"rerun+http://127.0.0.1:{_free_port()}/proxy"
    code, lines = invoke(["replay", str(small_log), "--connect", url])
    assert code == 1 and len(lines) == 1
    assert lines[0].startswith(f"Error: no Rerun viewer at {url}")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="X11/Wayland check")
@needs_viewer
def test_replay_spawn_without_display_is_exit_1(
    small_log: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    code, lines = invoke(["replay", str(small_log), "--spawn"])
    assert code == 1 and len(lines) == 1 and "--spawn needs a display" in lines[0]


def test_missing_matplotlib_names_the_extra(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib fails
    out = tmp_path / "exp"
    code, lines = invoke(["experiment", "paper", "--out", str(out), "--runs", "1"])
    assert code == 1 and len(lines) == 1
    assert "needs matplotlib" in lines[0] and "pip install 'bearing-slam[experiments]'" in lines[0]
    assert not out.exists()


def test_missing_distributed_names_the_extra(
    small_log: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "distributed", None)
    code, lines = invoke(["process", str(small_log), "--scheduler", "tcp://127.0.0.1:1"])
    assert code == 1 and len(lines) == 1
    assert "needs distributed" in lines[0] and "'experiments' extra" in lines[0]


@needs_experiments
def test_experiment_exits_1_when_no_run_succeeds(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from data_schemas.errors import BslamError

    def broken(*args: Any, **kwargs: Any) -> None:
        raise BslamError("the simulator is broken")

    monkeypatch.setattr("replay.experiments.run.simulate", broken)
    out = tmp_path / "exp"
    args = ["--out", str(out), "--runs", "2", "--movements", "2", "--workers", "1", "--quiet"]
    code, lines = invoke(["experiment", "paper", *args, "--n-l-values", ""])
    assert code == 1 and len(lines) == 1, lines
    assert "no run succeeded: all 2 failed" in lines[0] and "the simulator is broken" in lines[0]
    assert json.loads((out / "results.json").read_text())["runs"][0]["status"].startswith("failed")


@needs_viewer
def test_printed_commands_are_shell_quoted(tmp_path: Path, small_log: Path) -> None:
    import shlex

    rrd = tmp_path / "my run's replay.rrd"
    code, lines = invoke(["replay", str(small_log), "--save", str(rrd)])
    assert code == 0, lines
    hint = next(line for line in lines if "open it with: " in line).split("open it with: ")[1]
    assert shlex.split(hint)[1:] == [str(rrd)]
    folder = tmp_path / "stored logs"
    folder.mkdir()
    (folder / "a.mcap").write_bytes(small_log.read_bytes())
    (folder / "a.expected.json").write_text("[]")
    code, lines = invoke(["regress", str(folder)])
    assert code == 1
    assert shlex.split(lines[0].split("rewrite it with ")[1]) == [
        "bslam",
        "regress",
        str(folder),
        "--update",
    ]
