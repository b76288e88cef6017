"""Every schema we write passes the rules of Foxglove's JSON-schema channel parser.

Foxglove turns a channel's JSON Schema into message datatypes and rejects (the channel does not
load) a ``type`` that is a list (``["string", "null"]``: an optional field is simply not
required), an ``enum`` without its ``type``, and an array whose items are arrays.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from data_schemas.registry import TOPICS, schema_dict

SCHEMAS = sorted((Path(__file__).resolve().parents[2] / "data_schemas" / "schemas").glob("*.json"))


def _problems(node: Any, where: str) -> list[str]:
    found: list[str] = []
    if isinstance(node, dict):
        kind = node.get("type")
        if isinstance(kind, list):
            found.append(f"{where}: type is a list {kind}")
        if "enum" in node and not isinstance(kind, str):
            found.append(f"{where}: enum without a type")
        items = node.get("items")
        if kind == "array" and isinstance(items, dict) and items.get("type") == "array":
            found.append(f"{where}: array of arrays")
        for key, value in node.items():
            found += _problems(value, f"{where}.{key}")
    elif isinstance(node, list):
        for i, value in enumerate(node):
            found += _problems(value, f"{where}[{i}]")
    return found


def test_the_rules_catch_what_foxglove_rejects() -> None:
    bad = {
        "type": "object",
        "properties": {
            "reply": {"type": ["string", "null"]},
            "phase": {"enum": ["start", "end"]},
            "cov": {"type": "array", "items": {"type": "array", "items": {"type": "number"}}},
        },
    }
    assert len(_problems(bad, "bad")) == 3


@pytest.mark.parametrize("path", SCHEMAS, ids=lambda p: p.stem)
def test_schema_file_follows_foxglove_rules(path: Path) -> None:
    assert _problems(json.loads(path.read_text(encoding="utf-8")), path.stem) == []


@pytest.mark.parametrize("name", sorted({t.schema for t in TOPICS.values()}))
def test_registered_channel_schema_follows_foxglove_rules(name: str) -> None:
    # the self-contained form written into logs ($ref resolved)
    assert _problems(schema_dict(name), name) == []
