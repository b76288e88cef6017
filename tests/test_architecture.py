"""The import rule of docs/design.md, beyond what ruff's banned-api can see."""

from __future__ import annotations

import ast
import os
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


def _project_text_files() -> list[Path]:
    suffixes = {".py", ".md", ".toml", ".json", ".cfg", ".txt"}
    skip = {".venv", ".git", ".mypy_cache", ".hypothesis", ".benchmarks", "build", "__pycache__"}
    skip |= {"node_modules", ".venv-lowest"}  # the Node helper's packages, CI's second venv
    found = []
    for folder, dirs, files in os.walk(ROOT):
        dirs[:] = [d for d in dirs if d not in skip and not d.endswith(".egg-info")]
        found += [Path(folder) / f for f in files if Path(f).suffix in suffixes]
    return sorted(found)


def test_design_and_method_are_cited_inside_the_repository() -> None:
    # the design and the method live in docs/; nothing may send a reader outside the repository
    # spelled apart so this file is no hit; the last is the workplace the project was built in
    outside = ("DESIGN" + ".md", "METHOD" + ".md", "/" + "work/")
    hits = [
        f"{p.relative_to(ROOT)}: {name}"
        for p in _project_text_files()
        for name in outside
        if name in p.read_text(encoding="utf-8", errors="replace")
    ]
    assert hits == []
    for doc in ("docs/design.md", "docs/method.md"):
        assert (ROOT / doc).is_file()


def test_markdown_links_to_repository_files_exist() -> None:
    import re

    broken = []
    for p in _project_text_files():
        if p.suffix != ".md":
            continue
        for target in re.findall(r"\]\(([^)#\s]+)", p.read_text(encoding="utf-8")):
            if "://" not in target and not (p.parent / target).exists():
                broken.append(f"{p.relative_to(ROOT)} -> {target}")
    assert broken == []
