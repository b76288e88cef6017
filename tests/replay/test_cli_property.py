"""Generated bad input at the CLI: scenario files, option values, corrupted logs.

Whatever comes in, a command finishes with exit 0, 1 (a user error) or 2 (a usage error); an
error is at most two lines (the error and, for usage errors, a hint to --help) and never a
traceback. Examples are bounded and drawn by the deterministic profile of tests/conftest.py.
"""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path
from typing import Any

from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from replay.cli import cli

ROOT = Path(__file__).resolve().parents[2]
PAPER = json.loads((ROOT / "recorder/sim/scenarios/paper.json").read_text())
PAPER["trajectory"]["moves"] = 1  # a valid example simulates one movement only
PAPER["camera"].update(width=96, height=24)


def check(args: list[str]) -> int:
    """Run the CLI; assert the exit code and the shape of any error; return the code."""
    result = CliRunner().invoke(cli, args)
    # CliRunner catches everything: an exception other than SystemExit is a crash
    assert result.exception is None or isinstance(result.exception, SystemExit), (
        args,
        repr(result.exception),
    )
    assert result.exit_code in (0, 1, 2), (args, result.output)
    assert "Traceback" not in result.output
    if result.exit_code:
        lines = [line for line in result.output.splitlines() if line.strip()]
        errors = [line for line in lines if line.startswith("Error: ")]
        assert len(errors) == 1, (args, result.output)
        after = lines[lines.index(errors[0]) :]
        assert len(after) <= 2, (args, result.output)
    return result.exit_code


ODD = st.one_of(
    st.sampled_from([math.nan, math.inf, -math.inf, -1, 0, 1e308, -1e-9, 2**63]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.text(max_size=5),
    st.none(),
    st.booleans(),
    st.lists(st.integers(-3, 3), max_size=3),
    st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
)


def _paths(node: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    out = [prefix] if prefix else []
    if isinstance(node, dict):
        for k, v in node.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out += _paths(v, (*prefix, i))
    return out


PATHS = _paths(PAPER)


@st.composite
def scenarios(draw: st.DrawFn) -> dict[str, Any]:
    doc = copy.deepcopy(PAPER)
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(PATHS))
        node: Any = doc
        try:
            for key in path[:-1]:
                node = node[key]
            if draw(st.booleans()) and isinstance(node, dict):
                node.pop(path[-1], None)
            else:
                node[path[-1]] = draw(ODD)
        except (KeyError, IndexError, TypeError):
            continue  # an earlier change removed or replaced the parent
    return doc


@settings(max_examples=20)
@given(doc=scenarios())
def test_generated_scenario_files(tmp_path_factory: Any, doc: dict[str, Any]) -> None:
    folder = tmp_path_factory.mktemp("scenario")
    (folder / "s.json").write_text(json.dumps(doc))  # NaN/Infinity written as Python does
    check(["simulate", "--scenario", str(folder / "s.json"), "--out", str(folder / "o.mcap")])


VALUES = st.one_of(
    st.sampled_from(["nan", "inf", "-inf", "-1", "0", "1e400", "", "abc", "1,2", "--", "0x10"]),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-(2**40), 2**40).map(str),
    st.text(max_size=6),
)
#: (command and fixed arguments, options to fuzz); the scenario does not exist, so an option
#: that passes ends the command with exit 1 before any work is done.
TARGETS = [
    (
        ["simulate", "--scenario", "missing.json", "--out", "o.mcap"],
        ["--seed", "--rate", "--turn-noise", "--distance-noise", "--png-level", "--encoding"],
    ),
    (
        ["experiment", "paper", "--scenario", "missing.json", "--out", "o"],
        [
            "--runs",
            "--movements",
            "--n-r",
            "--n-l",
            "--priors",
            "--frame-change",
            "--workers",
            "--seed",
            "--n-l-values",
        ],
    ),
    (
        ["experiment", "sweep", "--scenario", "missing.json", "--out", "o", "--param", "n_l"],
        ["--values", "--runs", "--seed"],
    ),
    (["regress", "missing-folder"], ["--tolerance"]),
]


@settings(max_examples=40)
@given(
    target=st.sampled_from(TARGETS),
    picks=st.lists(st.tuples(st.integers(0, 20), VALUES), min_size=1, max_size=3),
)
def test_generated_option_values(
    tmp_path_factory: Any, target: tuple[list[str], list[str]], picks: list[tuple[int, str]]
) -> None:
    base, options = target
    folder = tmp_path_factory.mktemp("options")
    args = [str(folder / a) if a.startswith(("o", "missing")) else a for a in base]
    for i, value in picks:
        args += [options[i % len(options)], value]
    code = check(args)
    assert code in (1, 2)  # the scenario or log does not exist: nothing can succeed
    assert not (folder / "o").exists() and not (folder / "o.mcap").exists()


@settings(max_examples=15)
@given(
    picks=st.lists(
        st.tuples(st.sampled_from(["--seed", "--n-r", "--n-l", "--prior"]), VALUES),
        min_size=1,
        max_size=2,
    )
)
def test_generated_process_options(small_log: Path, picks: list[tuple[str, str]]) -> None:
    """On a real log: a value that passes runs the pipeline (the log is three movements)."""
    check(["process", str(small_log), *(x for pick in picks for x in pick)])


@settings(max_examples=12)
@given(data=st.data())
def test_corrupted_logs(tmp_path_factory: Any, small_log: Path, data: st.DataObject) -> None:
    raw = bytearray(small_log.read_bytes())
    how = data.draw(st.sampled_from(["flip", "truncate", "overwrite"]))
    if how == "truncate":
        raw = raw[: data.draw(st.integers(0, len(raw) - 1))]
    else:
        for _ in range(data.draw(st.integers(1, 8))):
            at = data.draw(st.integers(0, len(raw) - 1))
            raw[at] = data.draw(st.integers(0, 255)) if how == "overwrite" else raw[at] ^ 0xFF
    folder = tmp_path_factory.mktemp("corrupt")
    (folder / "bad.mcap").write_bytes(bytes(raw))
    check(["process", str(folder / "bad.mcap"), "--summary", str(folder / "map.json")])
