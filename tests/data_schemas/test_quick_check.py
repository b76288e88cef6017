"""data_schemas/quick_check.py against jsonschema: real documents of every kind pass the quick
check (so valid logs never import jsonschema), and on documents mutated at random it never
contradicts jsonschema (``None``, "ask jsonschema", is allowed)."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path
from typing import Any

import jsonschema
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader

from data_schemas import SchemaError
from data_schemas.codec import validate
from data_schemas.quick_check import conforms
from data_schemas.registry import SESSION_METADATA_NAME, schema_dict
from recorder.sim.scenario import BUILTIN_SCENARIOS, builtin_scenario
from replay.process import process_log
from replay.records import MethodConfig
from tests.mcap_reader import LogReader

REGRESS = Path(__file__).parents[1] / "data" / "regress"


def _log_docs(path: Path) -> list[tuple[str, Any]]:
    docs = [(m.schema, json.loads(m.data)) for m in LogReader(path).messages()]
    with path.open("rb") as f:
        for record in make_reader(f).iter_metadata():
            if record.name == SESSION_METADATA_NAME:
                docs.append(("bslam.Session", json.loads(record.metadata["json"])))
    return docs


@pytest.fixture(scope="module")
def real_docs(tmp_path_factory: pytest.TempPathFactory) -> list[tuple[str, Any]]:
    """(schema, document) of every kind a log, a derived log, a scenario and a session hold."""
    derived = tmp_path_factory.mktemp("quick") / "derived.mcap"
    process_log(REGRESS / "unwrapped.mcap", MethodConfig(), out=derived)
    docs = _log_docs(REGRESS / "unwrapped.mcap") + _log_docs(REGRESS / "omni.mcap")
    docs += _log_docs(derived)
    docs += [("bslam.Scenario", builtin_scenario(name).to_dict()) for name in BUILTIN_SCENARIOS]
    docs += [
        ("bslam.Scenario", json.loads(path.read_text()))
        for path in sorted(REGRESS.glob("*.scenario.json"))
    ]
    docs += [
        ("bslam.Calibration", doc["camera"]["calibration"])
        for schema, doc in docs
        if schema == "bslam.Session" and "calibration" in doc["camera"]
    ]
    return docs


def test_every_real_document_passes_without_jsonschema(real_docs: list[tuple[str, Any]]) -> None:
    kinds = {schema for schema, _ in real_docs}
    # raw (6 channels, Foxglove's image and log among them), derived (4, and 4 of Foxglove's for
    # its 3D panel), scenario, session and calibration (unwrapped and omni) documents
    assert len(kinds) == 17, sorted(kinds)
    assert sum(schema == "bslam.Calibration" for schema, _ in real_docs) >= 2
    for schema, doc in real_docs:
        assert conforms(schema_dict(schema), doc) is True, schema
        assert jsonschema.Draft202012Validator(schema_dict(schema)).is_valid(doc)


def _shrunk(doc: Any) -> Any:
    """The document with long arrays cut to 4 items (the mutations below do the rest)."""
    if isinstance(doc, dict):
        return {k: _shrunk(v) for k, v in doc.items()}
    if isinstance(doc, list):
        return [_shrunk(v) for v in doc[:4]]
    return doc


JSON_SCALARS = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**40), max_value=2**40),
    st.sampled_from([0, 1, -1, 2, 0.0, -0.0, 0.5, 1.0, -1.5, 90.0, 1e9, math.nan, math.inf]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from(["", "start", "end", "red", "unwrapped", "omni", "L1", "x"]),
    st.text(max_size=4),
)
JSON_VALUES = st.recursive(
    JSON_SCALARS,
    lambda inner: st.one_of(
        st.lists(inner, max_size=3), st.dictionaries(st.sampled_from(["a", "x", "sec"]), inner)
    ),
    max_leaves=6,
)


def _mutate(doc: Any, data: st.DataObject) -> Any:
    """One random change somewhere in ``doc`` (a copy): a value replaced, a key deleted or added,
    an item dropped or repeated, a list emptied."""
    doc = copy.deepcopy(doc)
    parent: Any = None
    key: Any = None
    node = doc
    while isinstance(node, dict | list) and node and data.draw(st.booleans()):
        keys = list(node) if isinstance(node, dict) else list(range(len(node)))
        parent, key = node, data.draw(st.sampled_from(keys))
        node = node[key]
    action = data.draw(st.sampled_from(["replace", "delete", "add", "repeat", "empty"]))
    if action == "replace" or (parent is None and action == "delete"):
        value = data.draw(JSON_VALUES)
        if parent is None:
            return value
        parent[key] = value
    elif action == "delete":
        del parent[key]
    elif action == "add" and isinstance(node, dict):
        node[data.draw(st.sampled_from(["extra", "x", "sec", "data"]))] = data.draw(JSON_VALUES)
    elif action == "repeat" and isinstance(node, list) and node:
        node.append(copy.deepcopy(node[0]))
    elif action == "empty" and isinstance(node, dict | list):
        node.clear()
    return doc


@settings(max_examples=400)
@given(data=st.data())
def test_never_contradicts_jsonschema(
    real_docs: list[tuple[str, Any]], data: st.DataObject
) -> None:
    schema_name, doc = data.draw(st.sampled_from(real_docs))
    doc = _shrunk(doc)
    for _ in range(data.draw(st.integers(1, 3))):
        doc = _mutate(doc, data)
    schema = schema_dict(schema_name)
    verdict = conforms(schema, doc)
    if verdict is not None:
        assert verdict == jsonschema.Draft202012Validator(schema).is_valid(doc), (schema_name, doc)


def test_an_invalid_document_still_gets_jsonschemas_one_line() -> None:
    scenario = builtin_scenario("paper").to_dict()
    scenario["camera"]["width"] = -5
    assert conforms(schema_dict("bslam.Scenario"), scenario) is False
    with pytest.raises(SchemaError, match=r"^scenario: field 'camera.width': -5 is less than"):
        validate("bslam.Scenario", scenario, what="scenario")


def test_keywords_by_hand_and_unknown_ones_left_to_jsonschema() -> None:
    assert conforms({"type": "string", "pattern": "^a"}, "b") is None
    assert conforms({"type": "number"}, 1.5) is True
    assert conforms({"enum": ["a", "b"]}, 2.0) is None  # 2.0 == 2 in JSON: not judged here
    assert conforms({"type": "integer"}, True) is False  # a boolean is not a number in JSON
    assert conforms({"type": "integer"}, 3.0) is True
    assert conforms({"items": {"type": "number"}}, [1, 2.5, "x"]) is False
    assert conforms({"oneOf": [{"type": "number"}, {"type": "integer"}]}, 1) is False  # both
    assert conforms({"oneOf": [{"type": "number"}, {"type": "integer"}]}, 1.5) is True
