"""Scenario files: the shipped ones load; every mistake is one ScenarioError naming the key."""

from __future__ import annotations

import copy
import json
import math
from collections.abc import Callable
from importlib import resources
from pathlib import Path
from typing import Any

import pytest

from data_schemas.calibration import OmniCalibration, UnwrappedCalibration
from data_schemas.codec import validate
from data_schemas.errors import ScenarioError
from data_schemas.paper_arena import PAPER_ARENA_M, PAPER_LANDMARKS_M, PAPER_REFERENCE
from recorder.sim.scenario import (
    BUILTIN_SCENARIOS,
    builtin_scenario,
    load_scenario,
    scenario_from_dict,
)


def paper_doc() -> dict[str, Any]:
    text = resources.files("recorder.sim").joinpath("scenarios", "paper.json").read_text()
    doc: dict[str, Any] = json.loads(text)
    return doc


def test_paper_scenario_matches_the_paper() -> None:
    s = builtin_scenario("paper")
    assert (s.arena.width_m, s.arena.height_m) == (1.05, 0.68)
    assert [(lm.name, lm.color) for lm in s.landmarks] == [
        ("L1", "red"),
        ("L2", "green"),
        ("L3", "blue"),
        ("L4", "yellow"),
    ]
    l1, l2 = s.landmark("L1"), s.landmark("L2")
    assert math.hypot(l2.x - l1.x, l2.y - l1.y) == pytest.approx(0.30)
    assert s.reference == ("L1", "L2")
    assert s.vision_error_rad == pytest.approx(math.radians(3.0))
    assert s.camera.bearing_noise_rad == pytest.approx(math.radians(1.0))
    assert s.trajectory.random_count == 10
    assert s.trajectory.distance_range_m == (0.10, 0.25)
    assert s.trajectory.seed == 7
    cal = s.calibration()
    assert isinstance(cal, UnwrappedCalibration)
    assert (cal.width, cal.height) == (255, 176)


@pytest.mark.parametrize("name", ["paper", "paper_omni"])
def test_paper_scenarios_place_the_paper_arena(name: str) -> None:
    # data_schemas.paper_arena is the paper's geometry; the built-in files must agree with it
    s = builtin_scenario(name)
    assert (s.arena.width_m, s.arena.height_m) == PAPER_ARENA_M
    assert {lm.name: (lm.x, lm.y) for lm in s.landmarks} == PAPER_LANDMARKS_M
    assert s.reference == PAPER_REFERENCE


def test_omni_scenario_has_an_omni_calibration() -> None:
    cal = builtin_scenario("paper_omni").calibration()
    assert isinstance(cal, OmniCalibration)
    assert (cal.width, cal.height) == (320, 320)


@pytest.mark.parametrize("name", BUILTIN_SCENARIOS)
def test_to_dict_validates_and_round_trips(name: str) -> None:
    s = builtin_scenario(name)
    doc = s.to_dict()
    validate("bslam.Scenario", doc)
    assert scenario_from_dict(doc) == s
    assert doc["vision_error_deg"] == 3.0


def test_load_from_file_and_seed_override(tmp_path: Path) -> None:
    path = tmp_path / "s.json"
    path.write_text(json.dumps(paper_doc()))
    s = load_scenario(path)
    assert s == builtin_scenario("paper")
    assert s.with_seed(11).trajectory.seed == 11
    assert s.with_seed(11).landmarks == s.landmarks


def test_explicit_moves_and_start_heading() -> None:
    doc = paper_doc()
    del doc["trajectory"]["distance"]
    doc["trajectory"]["start"] = [0.52, 0.34, 90]
    doc["trajectory"]["moves"] = [
        {"turn_deg": 0, "distance": 0.1},
        {"turn_deg": -90, "distance": 0.2},
    ]
    s = scenario_from_dict(doc)
    assert s.trajectory.start_world[2] == pytest.approx(math.pi / 2)
    assert s.trajectory.moves is not None
    assert [m.distance_m for m in s.trajectory.moves] == [0.1, 0.2]
    assert s.trajectory.moves[1].turn_rad == pytest.approx(-math.pi / 2)
    assert s.trajectory.n_moves == 2
    # and back to degrees (a round trip alone would hide a unit error made both ways)
    back = s.to_dict()
    assert back["trajectory"]["start"] == [0.52, 0.34, 90.0]
    assert [m["turn_deg"] for m in back["trajectory"]["moves"]] == [0.0, -90.0]
    assert back["camera"]["bearing_noise_deg"] == 1.0 and back["vision_error_deg"] == 3.0


Edit = Callable[[dict[str, Any]], None]


def _set(path: str, value: Any) -> Edit:
    def edit(doc: dict[str, Any]) -> None:
        *parents, last = path.split(".")
        node: Any = doc
        for p in parents:
            node = node[int(p)] if p.isdigit() else node[p]
        node[int(last) if last.isdigit() else last] = value

    return edit


def _rename(old: str, new: str) -> Edit:
    def edit(doc: dict[str, Any]) -> None:
        doc[new] = doc.pop(old)

    return edit


def _explicit(moves: list[dict[str, float]]) -> Edit:
    def edit(doc: dict[str, Any]) -> None:
        del doc["trajectory"]["distance"]
        doc["trajectory"]["moves"] = moves

    return edit


CASES: list[tuple[str, Edit, list[str]]] = [
    (
        "typo top level",
        _rename("landmarks", "landmark"),
        ["'landmark'", "did you mean 'landmarks'"],
    ),
    ("unknown camera key", _set("camera.noise_deg", 1.0), ["'camera.noise_deg'"]),
    ("unknown landmark key", _set("landmarks.2.colour", "red"), ["'landmarks[2].colour'"]),
    (
        "unknown move key",
        _explicit([{"turn_deg": 10, "distance": 0.1, "speed": 1}]),
        ["'trajectory.moves[0].speed'"],
    ),
    ("missing key", lambda d: d.pop("vision_error_deg"), ["vision_error_deg"]),
    ("wrong type", _set("arena.width", "wide"), ["arena.width"]),
    ("bad colour", _set("landmarks.0.color", "purple"), ["landmarks.0.color", "purple"]),
    ("landmark outside", _set("landmarks.3.x", 1.2), ["'landmarks[3]'", "outside"]),
    ("duplicate name", _set("landmarks.1.name", "L1"), ["'landmarks[1].name'", "duplicate"]),
    ("unknown reference", _set("reference", ["L1", "L9"]), ["'reference'", "'L9'"]),
    ("same reference", _set("reference", ["L1", "L1"]), ["'reference'", "differ"]),
    ("start on a landmark", _set("trajectory.start", [0.21, 0.2]), ["'trajectory.start'", "L3"]),
    ("start outside", _set("trajectory.start", [1.3, 0.2]), ["'trajectory.start'", "outside"]),
    (
        "inverted range",
        _set("trajectory.distance", [0.3, 0.1]),
        ["'trajectory.distance'", "inverted"],
    ),
    ("random without range", lambda d: d["trajectory"].pop("distance"), ["'trajectory.distance'"]),
    (
        "explicit move leaves",
        _explicit([{"turn_deg": 0, "distance": 0.1}, {"turn_deg": 0, "distance": 0.5}]),
        ["'trajectory.moves[1]'", "wall"],
    ),
    (
        "explicit move hits landmark",
        _explicit([{"turn_deg": -156.4, "distance": 0.3}]),
        ["'trajectory.moves[0]'", "landmark"],
    ),
    (
        "explicit move passes through landmark",
        lambda d: (
            _set("trajectory.start", [0.1, 0.55])(d),
            _explicit([{"turn_deg": 0, "distance": 0.5}])(d),
        ),
        ["'trajectory.moves[0]'", "L1"],
    ),
]


@pytest.mark.parametrize(("edit", "needles"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_scenario_errors_name_the_key(edit: Edit, needles: list[str]) -> None:
    doc = copy.deepcopy(paper_doc())
    edit(doc)
    with pytest.raises(ScenarioError) as info:
        scenario_from_dict(doc, what="scenario s.json")
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith("scenario s.json: ")
    for needle in needles:
        assert needle in message


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match="does not exist"):
        load_scenario(tmp_path / "nope.json")


def test_not_json(tmp_path: Path) -> None:
    path = tmp_path / "bad.json"
    path.write_text('{"arena": {"width": 1.0,')
    with pytest.raises(ScenarioError, match=r"bad\.json: not valid JSON \(line 1"):
        load_scenario(path)


def test_not_an_object(tmp_path: Path) -> None:
    path = tmp_path / "list.json"
    path.write_text("[1, 2]")
    with pytest.raises(ScenarioError, match="must be a JSON object"):
        load_scenario(path)


def test_unknown_builtin() -> None:
    with pytest.raises(ScenarioError, match="paper_omni"):
        builtin_scenario("nope")


def test_pinhole_scenario_camera() -> None:
    """A pinhole camera 60 deg wide over 320 columns has fx = 160 / tan(30 deg); its
    distortion is kept; it round-trips; fov_deg on a panorama, or a bad distortion, is refused."""
    from data_schemas.calibration import PinholeCalibration

    doc = paper_doc()
    doc["camera"] = {
        "model": "pinhole",
        "width": 320,
        "height": 240,
        "fov_deg": 60,
        "distortion": [-0.2, 0.05, 0, 0],
    }
    s = scenario_from_dict(doc)
    cal = s.calibration()
    assert isinstance(cal, PinholeCalibration)
    assert cal.fx == pytest.approx(160.0 / math.tan(math.radians(30.0)))
    assert (cal.cx, cal.cy, cal.distortion) == (159.5, 119.5, (-0.2, 0.05, 0.0, 0.0))
    assert scenario_from_dict(s.to_dict()) == s
    validate("bslam.Scenario", s.to_dict())
    panorama = paper_doc()
    panorama["camera"]["fov_deg"] = 60
    with pytest.raises(ScenarioError, match="fov_deg and distortion are for a pinhole camera"):
        scenario_from_dict(panorama)
    doc["camera"]["distortion"] = [0.1]
    with pytest.raises(ScenarioError, match="takes 4 or 5 coefficients"):
        scenario_from_dict(doc)
