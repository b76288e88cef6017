"""Coded landmarks in scenarios and landmark catalogs: the contract, its errors, generators."""

from __future__ import annotations

import json
import math
from itertools import pairwise
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from data_schemas.codec import validate
from data_schemas.errors import ScenarioError, SchemaError
from data_schemas.session import LandmarkSpec
from recorder.session import load_landmark_file
from recorder.sim.coded import band_codes, coded_landmarks, with_coded_landmarks
from recorder.sim.scenario import builtin_scenario, scenario_from_dict


def _coded_doc() -> dict[str, Any]:
    doc = builtin_scenario("paper").to_dict()
    doc["landmarks"][2] = {"name": "L3", "x": 0.2, "y": 0.2, "bands": ["magenta", "yellow"]}
    doc["landmarks"].append({"name": "L5", "x": 0.9, "y": 0.5, "bands": ["cyan", "red", "blue"]})
    return doc


def test_a_coded_scenario_loads_and_round_trips() -> None:
    s = scenario_from_dict(_coded_doc())
    l3, l5 = s.landmark("L3"), s.landmark("L5")
    assert (l3.color, l3.bands, l3.label) == (None, ("magenta", "yellow"), "magenta-yellow")
    assert l5.bands == ("cyan", "red", "blue") and s.landmark("L1").label == "red"
    doc = s.to_dict()
    validate("bslam.Scenario", doc)
    assert doc["landmarks"][2] == {
        "name": "L3",
        "x": 0.2,
        "y": 0.2,
        "bands": ["magenta", "yellow"],
        "radius": 0.01,
        "height": 0.15,
    }
    assert scenario_from_dict(doc) == s


def _landmark(i: int, **keys: Any) -> Any:
    def edit(doc: dict[str, Any]) -> None:
        entry = {k: v for k, v in doc["landmarks"][i].items() if k not in ("color", "bands")}
        doc["landmarks"][i] = entry | keys

    return edit


@pytest.mark.parametrize(
    ("edit", "needles"),
    [
        (_landmark(2, color="blue", bands=["red", "green"]), ["landmarks[2]", "not both"]),
        (_landmark(2), ["landmarks[2]", "needs 'color'", "'bands'"]),
        (_landmark(2, bands=["red"]), ["landmarks[2]", "two or more bands"]),
        (_landmark(2, bands=["red", "red"]), ["landmarks[2]", "adjacent bands"]),
        (_landmark(2, bands=["red", "teal"]), ["landmarks.2.bands.1", "teal"]),
        (_landmark(2, color="red"), ["'reference'", "'L1' shares its class 'red' with L3"]),
        (
            _landmark(1, bands=["cyan", "red", "blue"]),
            ["'reference'", "'L2' shares its class 'cyan-red-blue' with L5"],
        ),
    ],
)
def test_appearance_errors_are_one_line_naming_the_landmark(edit: Any, needles: list[str]) -> None:
    doc = _coded_doc()
    edit(doc)
    with pytest.raises(ScenarioError) as info:
        scenario_from_dict(doc, what="scenario s.json")
    message = str(info.value)
    assert "\n" not in message and message.startswith("scenario s.json: ")
    for needle in needles:
        assert needle in message, message


def test_landmarks_alike_are_allowed_outside_the_reference_pair() -> None:
    doc = _coded_doc()
    _landmark(4, bands=["magenta", "yellow"])(doc)  # L5 now looks like L3
    s = scenario_from_dict(doc)
    assert s.landmark("L5").label == s.landmark("L3").label


def _write(tmp_path: Path, doc: Any) -> Path:
    path = tmp_path / "landmarks.json"
    path.write_text(json.dumps(doc))
    return path


def test_landmark_file_takes_bands(tmp_path: Path) -> None:
    doc = {
        "landmarks": [
            {"name": "A", "color": "red"},
            {"name": "B", "bands": ["green", "magenta"]},
            {"name": "C", "bands": ["yellow", "blue", "yellow"]},
        ],
        "reference": ["A", "B"],
        "vision_error_deg": 2.0,
    }
    catalog = load_landmark_file(_write(tmp_path, doc))
    assert catalog.landmarks == (
        LandmarkSpec("A", "red"),
        LandmarkSpec("B", None, bands=("green", "magenta")),
        LandmarkSpec("C", None, bands=("yellow", "blue", "yellow")),
    )
    assert [lm.label for lm in catalog.landmarks] == ["red", "green-magenta", "yellow-blue-yellow"]


@pytest.mark.parametrize(
    ("landmarks", "needle"),
    [
        ([{"name": "A", "color": "red", "bands": ["red", "blue"]}], "not both"),
        ([{"name": "A"}], "needs 'color'"),
        ([{"name": "A", "bands": ["red", "red"]}], "adjacent bands"),
        ([{"name": "A", "color": "green"}], "'B' shares its class 'green' with A"),
    ],
)
def test_landmark_file_errors(tmp_path: Path, landmarks: list[Any], needle: str) -> None:
    doc = {
        "landmarks": [*landmarks, {"name": "B", "color": "green"}, {"name": "C", "color": "red"}],
        "reference": ["B", "C"],
    }
    with pytest.raises(SchemaError) as info:
        load_landmark_file(_write(tmp_path, doc))
    assert needle in str(info.value) and "\n" not in str(info.value)


def test_band_codes_are_distinct_and_valid() -> None:
    codes = band_codes(60)
    assert len(set(codes)) == 60
    assert all(len(c) in (2, 3) and all(a != b for a, b in pairwise(c)) for c in codes)
    assert all(len(c) == 2 for c in codes[:30])
    with pytest.raises(ScenarioError, match="at most"):
        band_codes(10_000)


def test_coded_landmarks_keep_their_spacing() -> None:
    docs = coded_landmarks(3.0, 2.0, 20, np.random.default_rng(1))
    xy = np.array([[d["x"], d["y"]] for d in docs])
    gaps = np.hypot(*(xy[:, None] - xy[None]).transpose(2, 0, 1))
    assert gaps[np.triu_indices(20, 1)].min() >= 0.25 - 1e-3
    assert (xy > 0.05).all() and (xy[:, 0] < 2.95).all() and (xy[:, 1] < 1.95).all()
    with pytest.raises(ScenarioError, match="cannot place 40 landmarks"):
        coded_landmarks(1.0, 0.6, 40, np.random.default_rng(1))


def test_with_coded_landmarks_makes_a_valid_scenario() -> None:
    base = builtin_scenario("paper").to_dict()
    base["arena"] = {"width": 3.0, "height": 2.0}
    base["trajectory"]["start"] = [1.5, 1.0]
    doc = with_coded_landmarks(base, 20, seed=3)
    s = scenario_from_dict(doc)
    assert len(s.landmarks) == 20 and s.reference == ("L1", "L2")
    assert len({lm.label for lm in s.landmarks}) == 20
    x, y, _ = s.trajectory.start_world
    assert min(math.hypot(lm.x - x, lm.y - y) for lm in s.landmarks) >= 0.125
    assert with_coded_landmarks(base, 20, seed=3) == doc  # reproducible
