from __future__ import annotations

import json
import math

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
    with pytest.raises(SchemaError, match="'L9' is not in the landmark catalog"):
        session_from_doc(doc)


def test_unknown_colour_named() -> None:
    doc = _doc() | {"landmarks": [{"name": "L1", "color": "red"}, {"name": "L2", "color": "teal"}]}
    with pytest.raises(SchemaError, match=r"field 'landmarks.1.color'"):
        session_from_doc(doc)


def test_missing_json_key() -> None:
    with pytest.raises(MissingMetadataError):
        session_from_metadata({})
