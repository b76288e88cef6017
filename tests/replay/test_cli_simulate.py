"""`bslam simulate`: the real recorder against the simulated robot and camera, read back."""

from __future__ import annotations

import base64
import json
import math
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from data_schemas.angles import wrap_rad
from data_schemas.codec import validate
from data_schemas.colors import NOMINAL_BGR
from data_schemas.registry import TOPICS
from data_schemas.stamps import ns_from_stamp
from replay.cli import cli
from tests.mcap_reader import LogReader


def _simulate(out: Path, *args: str) -> list[tuple[str, dict[str, Any]]]:
    result = CliRunner().invoke(cli, ["simulate", "--out", str(out), *args])
    assert result.exit_code == 0, result.output
    with LogReader(out) as reader:
        return [(m.topic, m.decode()) for m in reader.messages()]


@pytest.fixture(scope="module")
def paper_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("sim") / "paper.mcap"
    _simulate(out, "--scenario", "paper", "--seed", "11")
    return out


def _measured_bearing(image: np.ndarray, color: str, cal: Any) -> float | None:
    """Circular mean bearing of the pixels near a landmark's nominal colour (None if absent)."""
    distance = np.linalg.norm(image.astype(float) - np.array(NOMINAL_BGR[color], float), axis=2)
    _, cols = np.nonzero(distance < 80)
    if cols.size == 0:
        return None
    b = cal.bearing_of_column(cols + 0.5)
    return math.atan2(float(np.sin(b).mean()), float(np.cos(b).mean()))


def test_every_message_validates_and_session_is_simulated(paper_log: Path) -> None:
    with LogReader(paper_log) as reader:
        session = reader.session()
        msgs = list(reader.messages())
    assert session.simulated and session.scenario is not None
    assert session.doc["simulation"]["seed"] == 11
    for m in msgs:
        validate(TOPICS[m.topic].schema, m.decode(), what=m.topic)
    # a stop-and-go session has neither a driving robot's odometry poses nor a bearing sensor,
    # nor the outside truth of an imported log
    driving = {"/robot/odometry_pose", "/sensor/bearings", "/truth/robot_pose"}
    recorded = {t for t in TOPICS if not t.startswith("/pipeline/")} - driving
    assert {m.topic for m in msgs} == recorded
    starts = [m for m in msgs if m.topic == "/robot/movement" and m.decode()["phase"] == "start"]
    assert len(starts) == 10  # the paper scenario's moves


def test_keyframe_bearings_agree_with_ground_truth(paper_log: Path) -> None:
    """The simulator is right: landmarks appear in the logged keyframes where the logged true
    poses say they should, within the vision error bound."""
    with LogReader(paper_log) as reader:
        session = reader.session()
        msgs = [(m.topic, m.decode()) for m in reader.messages()]
    frames = {ns_from_stamp(m["timestamp"]): m for t, m in msgs if t == "/camera/panorama"}
    truth = {ns_from_stamp(m["timestamp"]): m for t, m in msgs if t == "/sim/ground_truth"}
    assert set(truth) == set(frames)
    landmarks = session.scenario["landmarks"] if session.scenario else []
    eps_deg = math.degrees(session.vision_error_rad)
    column_deg = 360.0 / session.calibration.width
    errors_deg = []
    for topic_name, m in msgs:
        if topic_name != "/robot/movement":
            continue
        key = ns_from_stamp(m["keyframe_timestamp"])
        png = np.frombuffer(base64.b64decode(frames[key]["data"]), np.uint8)
        image = cv2.imdecode(png, cv2.IMREAD_COLOR)
        pose = truth[key]
        for lm in landmarks:
            measured = _measured_bearing(image, lm["color"], session.calibration)
            if measured is None:
                continue  # hidden behind another landmark
            expected = math.atan2(lm["y"] - pose["y"], lm["x"] - pose["x"]) - pose["heading"]
            errors_deg.append(math.degrees(wrap_rad(measured - expected)))
    errors = np.array(errors_deg)
    assert errors.size >= 0.9 * 20 * len(landmarks)  # nearly every landmark in every keyframe
    assert np.abs(errors).max() <= eps_deg + column_deg / 2  # noise truncated at eps
    noise_deg = session.scenario["camera"]["bearing_noise_deg"] if session.scenario else 0
    assert 0.5 * noise_deg < errors.std() < 1.5 * noise_deg  # the scenario's bearing noise
    assert abs(errors.mean()) < 0.5


def test_true_motion_follows_the_commands(paper_log: Path) -> None:
    with LogReader(paper_log) as reader:
        msgs = [(m.topic, m.decode()) for m in reader.messages()]
    truth = {ns_from_stamp(m["timestamp"]): m for t, m in msgs if t == "/sim/ground_truth"}
    moves = [m for t, m in msgs if t == "/robot/movement"]
    for start, end in zip(moves[::2], moves[1::2], strict=True):
        a = truth[ns_from_stamp(start["keyframe_timestamp"])]
        b = truth[ns_from_stamp(end["keyframe_timestamp"])]
        travelled = math.hypot(b["x"] - a["x"], b["y"] - a["y"])
        assert travelled == pytest.approx(start["distance_m"], rel=0.1)  # 2 % actuation noise
        direction = math.atan2(b["y"] - a["y"], b["x"] - a["x"])
        assert abs(wrap_rad(direction - a["heading"])) < 0.05  # straight ahead
    for prev_end, start in zip(moves[1:-1:2], moves[2::2], strict=True):
        h0 = truth[ns_from_stamp(prev_end["keyframe_timestamp"])]["heading"]
        h1 = truth[ns_from_stamp(start["keyframe_timestamp"])]["heading"]
        turned = wrap_rad(h1 - h0)
        assert turned == pytest.approx(start["turn_rad"], rel=0.1, abs=0.02)


def test_same_seed_same_frames(paper_log: Path, tmp_path: Path) -> None:
    again = _simulate(tmp_path / "again.mcap", "--scenario", "paper", "--seed", "11")
    with LogReader(paper_log) as reader:
        first = [(m.topic, m.decode()) for m in reader.messages()]
    keep = ("/camera/panorama", "/sim/ground_truth", "/robot/movement")
    assert [x for x in again if x[0] in keep] == [x for x in first if x[0] in keep]


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"arena": {"width": 1.0, "hieght": 0.5}}, "hieght"),
        ({"reference": ["L1", "L9"]}, "reference"),
        ({"vision_error_deg": "three"}, "vision_error_deg"),
    ],
)
def test_scenario_errors_exit_1_with_one_line(
    tmp_path: Path, change: dict[str, Any], message: str
) -> None:
    doc = {
        "arena": {"width": 1.05, "height": 0.68},
        "landmarks": [
            {"name": "L1", "x": 0.3, "y": 0.5, "color": "red"},
            {"name": "L2", "x": 0.7, "y": 0.5, "color": "green"},
        ],
        "reference": ["L1", "L2"],
        "camera": {"model": "unwrapped", "width": 64, "height": 32},
        "vision_error_deg": 3.0,
        "trajectory": {"start": [0.5, 0.3], "moves": 2, "distance": [0.05, 0.1]},
    } | change
    path = tmp_path / "s.json"
    path.write_text(json.dumps(doc))
    out = tmp_path / "o.mcap"
    result = CliRunner().invoke(cli, ["simulate", "--scenario", str(path), "--out", str(out)])
    assert result.exit_code == 1
    assert result.output.count("\n") == 1 and message in result.output
    assert not out.exists()


def test_missing_scenario_file(tmp_path: Path) -> None:
    result = CliRunner().invoke(
        cli, ["simulate", "--scenario", str(tmp_path / "nope.json"), "--out", str(tmp_path / "o")]
    )
    assert result.exit_code == 1 and result.output.count("\n") == 1
