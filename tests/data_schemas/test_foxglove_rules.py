"""Every channel schema we write passes the checks of Foxglove's JSON-schema channel parser.

Foxglove (and Lichtblick, its open-source continuation) turns a ``json`` channel's JSON Schema
into message datatypes, walking it from the root, and the channel does not load if the walk
fails. What the walk accepts (``parseJsonSchema`` in their ``mcap-support`` package):

* the root, and every nested object, has ``"type": "object"`` (its ``properties`` may be absent);
* every property has a ``type`` that is one string of ``boolean``, ``string``, ``number``,
  ``integer``, ``object`` or ``array``: no list of types (an optional field is simply not
  required), no ``"null"``, no enum or ``$ref`` without its ``type``;
* a property with ``oneOf`` is an enum whose alternatives are all numeric ``const`` values;
* a string's only ``contentEncoding`` is ``base64``;
* an array's ``items`` has a ``type`` of the same list: no arrays of arrays (a covariance is
  ``{xx, xy, yy}`` or a flat list), and its strings carry no ``contentEncoding``.

Integers are shown as numbers, whatever their size. Schemas that are not channel schemas (the
session and scenario documents, written as metadata) are not walked by it.
"""

from __future__ import annotations

from typing import Any

import pytest

from data_schemas.registry import IMAGE_SCHEMAS, TOPICS, schema_dict

#: What a property or an array item may be.
_TYPES = ("boolean", "string", "number", "integer", "object", "array")
CHANNEL_SCHEMAS = sorted({t.schema for t in TOPICS.values()} | set(IMAGE_SCHEMAS))


def _object_problems(node: Any, where: str) -> list[str]:
    """What Foxglove's walk would refuse in the object schema ``node``."""
    if not isinstance(node, dict) or node.get("type") != "object":
        kind = node.get("type") if isinstance(node, dict) else node
        return [f'{where}: expected "type": "object", got {kind!r}']
    found: list[str] = []
    for name, prop in (node.get("properties") or {}).items():
        found += _property_problems(prop, f"{where}.{name}")
    return found


def _property_problems(prop: Any, where: str) -> list[str]:
    if not isinstance(prop, dict):
        return [f"{where}: not a schema"]
    if isinstance(prop.get("oneOf"), list):
        if all(isinstance(a, dict) and _is_number(a.get("const")) for a in prop["oneOf"]):
            return []
        return [f"{where}: oneOf alternatives must all be numeric consts"]
    kind = prop.get("type")
    if kind not in _TYPES:
        return [f"{where}: type {kind!r} (one of {', '.join(_TYPES)})"]
    if kind == "string" and prop.get("contentEncoding", "base64") != "base64":
        return [f"{where}: contentEncoding {prop['contentEncoding']!r}"]
    if kind == "object":
        return _object_problems(prop, where)
    if kind == "array":
        items = prop.get("items")
        item_kind = items.get("type") if isinstance(items, dict) else None
        if item_kind not in _TYPES or item_kind == "array":
            return [f"{where}: array items of type {item_kind!r}"]
        if item_kind == "string" and "contentEncoding" in items:
            return [f"{where}: array items with a contentEncoding"]
        if item_kind == "object":
            return _object_problems(items, f"{where}[]")
    return []


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def test_the_rules_catch_what_foxglove_rejects() -> None:
    bad = {
        "type": "object",
        "properties": {
            "reply": {"type": ["string", "null"]},
            "phase": {"enum": ["start", "end"]},
            "cov": {"type": "array", "items": {"type": "array", "items": {"type": "number"}}},
            "nothing": {"type": "null"},
            "ref": {"$ref": "bslam.Time.json"},
            "mode": {"oneOf": [{"const": "a"}, {"const": "b"}]},
            "text": {"type": "string", "contentEncoding": "gzip"},
            "blobs": {"type": "array", "items": {"type": "string", "contentEncoding": "base64"}},
            "loose": {"type": "array"},
            "inner": {"type": "object", "properties": {"x": {"type": "float"}}},
        },
    }
    problems = _object_problems(bad, "bad")
    assert len(problems) == 10, problems
    assert _object_problems({"properties": {}}, "root") == [
        'root: expected "type": "object", got None'
    ]


def test_the_rules_accept_what_foxglove_accepts() -> None:
    good = {
        "type": "object",
        "properties": {
            "level": {"oneOf": [{"title": "INFO", "const": 2}, {"title": "WARN", "const": 3}]},
            "data": {"type": "string", "contentEncoding": "base64"},
            "phase": {"type": "string", "enum": ["start", "end"]},
            "points": {
                "type": "array",
                "items": {"type": "object", "properties": {"x": {"type": "number"}}},
            },
            "free": {"type": "object"},  # no properties: an empty datatype
            "count": {"type": "integer"},
            "flags": {"type": "array", "items": {"type": "boolean"}},
        },
    }
    assert _object_problems(good, "good") == []


@pytest.mark.parametrize("name", CHANNEL_SCHEMAS)
def test_channel_schema_follows_foxglove_rules(name: str) -> None:
    # the self-contained form written into logs ($ref resolved)
    assert _object_problems(schema_dict(name), name) == []
