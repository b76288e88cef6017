"""The derived log's ``bslam.Detection`` comes from the Detection dataclass and its schema."""

from __future__ import annotations

from dataclasses import fields

import pytest

from data_schemas.codec import validate
from data_schemas.errors import SchemaError
from data_schemas.registry import schema_dict
from pipeline.bearings.blobs import Blob
from pipeline.bearings.detection import ClassSightings, Detection, detection_of
from replay.sinks.derived import detection_message, logged_detection_fields

BLOBS = (Blob(400, 0.5, 0.1), Blob(90, -2.0, 0.05))


def test_every_schema_field_is_a_dataclass_field_and_is_logged() -> None:
    declared = set(schema_dict("bslam.Detection")["properties"])
    assert set(logged_detection_fields()) == declared
    assert declared <= {f.name for f in fields(Detection)}


def test_seen_landmark_is_logged_with_its_values_and_validates() -> None:
    det = detection_of("L1", ClassSightings("red", ("L1",), BLOBS, 400), min_pixels=50)
    msg = detection_message(det)
    validate("bslam.Detection", msg)
    assert msg == {name: getattr(det, name) for name in logged_detection_fields()}
    assert msg["bearing_rad"] == 0.5 and msg["n_blobs"] == 2 and msg["reason"] == ""


def test_unseen_landmark_has_no_bearing_and_validates() -> None:
    sightings = ClassSightings("red", ("L1", "L2"), BLOBS, 400)
    det = detection_of("L1", sightings, min_pixels=50)
    msg = detection_message(det)
    validate("bslam.Detection", msg)
    assert "bearing_rad" not in msg and msg["visible"] is False
    assert "shared with L2" in msg["reason"]


def test_a_bearing_of_the_wrong_type_is_refused_by_the_schema() -> None:
    det = detection_of("L1", ClassSightings("red", ("L1",), BLOBS, 400), min_pixels=50)
    msg = detection_message(det) | {"bearing_rad": "0.5"}
    with pytest.raises(SchemaError):
        validate("bslam.Detection", msg)
