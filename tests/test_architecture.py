"""The import rule of DESIGN.md, beyond what ruff's banned-api can see."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _calls(package: str, name: str) -> list[str]:
    hits = []
    for path in sorted((ROOT / package).rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            call = isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
            if call and node.func.id == name:  # type: ignore[attr-defined]
                hits.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    return hits


def test_pipeline_opens_no_files() -> None:
    assert _calls("pipeline", "open") == []


def test_package_rules_are_configured() -> None:
    # each package carries its banned-api table; deleting one would silently drop the rule
    packages = ("data_schemas", "data_schemas/mcap", "recorder", "pipeline", "replay", "replay/cli")
    for package in packages:
        text = (ROOT / package / "ruff.toml").read_text(encoding="utf-8")
        assert "banned" in text, package
