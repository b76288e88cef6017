from __future__ import annotations

import json

import pytest

from data_schemas import SchemaError, decode, encode, schema_json, stamp_from_ns
from data_schemas.registry import TOPICS, schema_dict


def _movement() -> dict[str, object]:
    return {
        "timestamp": stamp_from_ns(1_500_000_000),
        "index": 0,
        "phase": "start",
        "keyframe_timestamp": stamp_from_ns(1_400_000_000),
        "turn_rad": 0.5,
        "distance_m": 0.2,
    }


def test_round_trip_movement() -> None:
    data = encode("/robot/movement", _movement())
    assert decode("/robot/movement", data, check=True) == _movement()
    # the bytes are the JSON of the message, as any reader decodes them
    assert json.loads(data) == _movement()
    assert json.loads(data)["timestamp"] == {"sec": 1, "nsec": 500_000_000}


def test_error_names_topic_and_field() -> None:
    bad = _movement() | {"phase": "middle"}
    with pytest.raises(SchemaError, match=r"^/robot/movement: field 'phase': 'middle' is not one"):
        encode("/robot/movement", bad)


def test_nested_field_path_is_named() -> None:
    bad = _movement() | {"timestamp": {"sec": 1, "nsec": -3}}
    with pytest.raises(SchemaError, match=r"field 'timestamp.nsec'"):
        encode("/robot/movement", bad)


def test_missing_required_field() -> None:
    bad = _movement()
    del bad["index"]
    with pytest.raises(SchemaError, match="field 'index': is missing"):
        encode("/robot/movement", bad)


def test_decode_rejects_non_json() -> None:
    with pytest.raises(SchemaError, match="not valid JSON"):
        decode("/log", b"\xff\x00")


@pytest.mark.parametrize("name", sorted({t.schema for t in TOPICS.values()}))
def test_registered_schemas_are_self_contained(name: str) -> None:
    text = schema_json(name).decode()
    assert '"$ref"' not in text
    assert json.loads(text)["title"] == name


def test_stamp_split() -> None:
    assert stamp_from_ns(3_000_000_007) == {"sec": 3, "nsec": 7}
    with pytest.raises(ValueError):
        stamp_from_ns(-1)


def test_session_schema_inlines_calibration() -> None:
    cal = schema_dict("bslam.Session")["properties"]["camera"]["properties"]["calibration"]
    assert "oneOf" in cal


def _particles(x: list[object]) -> dict[str, object]:
    point_set = {"name": "L3", "x": x, "y": [0.5] * len(x)}
    return {
        "timestamp": stamp_from_ns(1),
        "index": 0,
        "landmarks": [point_set],
        "observation_points": [],
    }


@pytest.mark.parametrize(
    ("value", "message"),
    [
        (True, r"field 'landmarks.0.x.2': True is not of type 'number'"),
        ("0.3", r"field 'landmarks.0.x.2': '0.3' is not of type 'number'"),
        ([0.3], r"field 'landmarks.0.x.2': \[0.3\] is not of type 'number'"),
        (None, r"field 'landmarks.0.x.2': None is not of type 'number'"),
        (float("nan"), r"field 'landmarks.0.x.2': must be a finite number, got nan"),
        (float("-inf"), r"field 'landmarks.0.x.2': must be a finite number, got -inf"),
    ],
)
def test_arrays_of_numbers_are_checked_item_by_item(value: object, message: str) -> None:
    # plain numeric arrays take a one-pass check; every other item still fails by name
    encode("/pipeline/particles_fl", _particles([0.1, 2, 0.3, -4.0]))
    with pytest.raises(SchemaError, match="^/pipeline/particles_fl: " + message):
        encode("/pipeline/particles_fl", _particles([0.1, 2, value, -4.0]))
