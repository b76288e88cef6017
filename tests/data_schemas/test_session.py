from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest

from data_schemas.calibration import UnwrappedCalibration
from data_schemas.errors import MissingMetadataError, SchemaError
from data_schemas.session import session_from_doc, session_from_metadata


def _doc() -> dict[str, object]:
    return {
        "schema_version": 1,
        "software_version": "0.1.0",
        "created_unix_ns": 1,
        "simulated": True,
        "robot": {
            "model": "khepera2",
            "port": "sim://",
            "baudrate": 9600,
            "mm_per_pulse": 0.08,
            "wheel_base_m": 0.053,
        },
        "camera": {
            "source": "sim",
            "calibration": {"model": "unwrapped", "width": 255, "height": 176},
        },
        "landmarks": [{"name": "L1", "color": "red"}, {"name": "L2", "color": "green"}],
        "reference": ["L1", "L2"],
        "vision_error_deg": 3.0,
    }


def test_typed_view() -> None:
    s = session_from_metadata({"json": json.dumps(_doc())})
    assert s.landmark_names() == ["L1", "L2"]
    assert s.reference == ("L1", "L2")
    assert s.vision_error_rad == pytest.approx(math.radians(3))
    assert s.calibration == UnwrappedCalibration(255, 176)
    assert s.scenario is None


def test_reference_must_be_in_catalog() -> None:
    doc = _doc() | {"reference": ["L1", "L9"]}
    with pytest.raises(SchemaError, match="'reference': 'L9' is not a landmark of the catalog"):
        session_from_doc(doc)


def test_unknown_colour_named() -> None:
    doc = _doc() | {"landmarks": [{"name": "L1", "color": "red"}, {"name": "L2", "color": "teal"}]}
    with pytest.raises(SchemaError, match=r"field 'landmarks.1.color'"):
        session_from_doc(doc)


def test_missing_json_key() -> None:
    with pytest.raises(MissingMetadataError):
        session_from_metadata({})


def test_catalog_rules_are_the_same_everywhere() -> None:
    """Session documents, scenario files and the estimator refuse the same catalogs."""
    from data_schemas.catalog import catalog_problem
    from data_schemas.errors import EstimationError, ScenarioError
    from pipeline import BearingSlam
    from recorder.sim.scenario import builtin_scenario, scenario_from_dict

    cases = [
        (["A", "B", "A"], ["A", "B"], "landmarks[2].name", "duplicate landmark name 'A'"),
        (["A", "B"], ["A", "C"], "reference", "'C' is not a landmark of the catalog"),
        (["A", "B"], ["B", "B"], "reference", "the two reference landmarks must differ"),
    ]
    paper = builtin_scenario("paper").to_dict()
    for names, ref, field, problem in cases:
        found = catalog_problem(names, ref)
        assert found is not None and found[0] == field and problem in found[1]
        doc = {**paper, "reference": ref}
        doc["landmarks"] = [
            {**paper["landmarks"][i], "name": n, "x": 0.2 + 0.2 * i} for i, n in enumerate(names)
        ]
        with pytest.raises(ScenarioError, match=f"key '{re.escape(field)}': {problem}"):
            scenario_from_dict(doc)
        with pytest.raises(EstimationError, match=problem):
            BearingSlam(
                names,
                (ref[0], ref[1]),
                vision_error_rad=math.radians(3),
                rng=np.random.default_rng(0),
            )
    assert catalog_problem(["A", "B"], ["A", "B"]) is None


def _no_camera() -> dict[str, object]:
    doc = _doc()
    del doc["camera"], doc["robot"]
    doc["simulated"] = False
    doc["landmarks"] = [{"name": "beacon 1"}, {"name": "beacon 2"}, {"name": "beacon 3"}]
    doc["reference"] = ["beacon 2", "beacon 3"]
    return doc


def test_a_session_without_camera_knows_its_landmarks_by_name() -> None:
    s = session_from_doc(_no_camera())
    assert s.calibration is None
    assert [lm.label for lm in s.landmarks] == ["beacon 1", "beacon 2", "beacon 3"]
    assert s.provenance is None and s.truth_landmarks_m() is None


def test_name_only_landmarks_need_a_session_without_camera() -> None:
    doc = _doc()
    doc["landmarks"] = [{"name": "L1"}, {"name": "L2", "color": "green"}]
    with pytest.raises(SchemaError, match=r"'landmarks.0': needs 'color'"):
        session_from_doc(doc)


def test_provenance_and_truth_are_checked() -> None:
    entry = {"role": "bearings", "name": "b.csv", "sha256": "ab" * 32, "bytes": 10}
    prov = {"kind": "csv", "importer_version": 1, "files": [entry]}
    truth = {"source": "survey", "landmarks": [{"name": "beacon 1", "x_m": 1.0, "y_m": -2.0}]}
    s = session_from_doc(_no_camera() | {"provenance": prov, "truth": truth})
    assert s.provenance == prov
    assert s.truth_landmarks_m() == {"beacon 1": (1.0, -2.0)}
    unknown = {"source": "survey", "landmarks": [{"name": "beacon 9", "x_m": 0, "y_m": 0}]}
    with pytest.raises(SchemaError, match=r"'truth\.landmarks': 'beacon 9' is not in the catalog"):
        session_from_doc(_no_camera() | {"truth": unknown})
    with pytest.raises(SchemaError, match="importer_version"):
        session_from_doc(_no_camera() | {"provenance": {"kind": "csv", "files": []}})


def test_band_boxes_sizes_and_range_round_trip() -> None:
    """A coded landmark's per-band HSV boxes, landmark sizes and the catalog's range_m are
    read into the typed view and written back unchanged by the recorder's catalog entries."""
    from recorder.session import landmark_entry

    entries = [
        {"name": "L1", "color": "red", "hsv": {"lo": [170, 100, 40], "hi": [8, 255, 255]}},
        {
            "name": "L2",
            "bands": ["green", "magenta"],
            "hsv": [
                {"lo": [50, 90, 40], "hi": [70, 255, 255]},
                {"lo": [140, 90, 40], "hi": [160, 255, 255]},
            ],
            "width": 0.05,
            "height": 0.3,
        },
    ]
    s = session_from_doc(_doc() | {"landmarks": entries, "range_m": [0.2, 4.0]})
    assert s.range_m == (0.2, 4.0)
    assert s.landmarks[1].band_hsv == (
        ((50, 90, 40), (70, 255, 255)),
        ((140, 90, 40), (160, 255, 255)),
    )
    assert (s.landmarks[1].width_m, s.landmarks[1].height_m) == (0.05, 0.3)
    assert [landmark_entry(lm) for lm in s.landmarks] == entries
    with pytest.raises(SchemaError, match="'range_m': nearest 4 m must be below farthest 2 m"):
        session_from_doc(_doc() | {"range_m": [4.0, 2.0]})
