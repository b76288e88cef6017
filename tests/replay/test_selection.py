"""Selection and inspection: ``--from/--to``, ``bslam cat``, ``bslam split`` and ``bslam merge``.

Oracle: the mcap library's own reader on the same files (log times, topics, message bytes and
metadata), and movement times taken from it, not from our window code.
"""

from __future__ import annotations

import base64
import json
from collections import Counter
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner
from logfactory import MOVES, session_doc, write_log
from mcap.reader import make_reader
from viewer import needs_viewer

from data_schemas.mcap.window import Bound, WindowError, parse_bound
from replay.cli import cli


def _read(log: Path) -> list[tuple[str, int, dict[str, Any]]]:
    """(topic, log time, message) of every message, with the mcap library."""
    with log.open("rb") as f:
        return [
            (c.topic, m.log_time, json.loads(m.data))
            for _, c, m in make_reader(f).iter_messages(log_time_order=True)
        ]


def _metadata(log: Path) -> dict[str, dict[str, str]]:
    with log.open("rb") as f:
        return {m.name: dict(m.metadata) for m in make_reader(f).iter_metadata()}


def _movement_times(log: Path) -> dict[tuple[int, str], int]:
    return {(m["index"], m["phase"]): t for topic, t, m in _read(log) if topic == "/robot/movement"}


def _summary(*args: str) -> dict[str, Any]:
    """The summary JSON a command prints on stdout."""
    result = CliRunner().invoke(cli, list(args))
    assert result.exit_code == 0, result.output
    doc: dict[str, Any] = json.loads(result.stdout)
    return doc


def _run(*args: str) -> tuple[int, str]:
    result = CliRunner().invoke(cli, list(args))
    return result.exit_code, result.output


@pytest.mark.parametrize(
    ("text", "bound"),
    [
        ("12.5s", Bound(seconds=12.5)),
        ("0s", Bound(seconds=0.0)),
        (".5s", Bound(seconds=0.5)),
        ("m3", Bound(movement=3)),
        ("m0", Bound(movement=0)),
    ],
)
def test_bounds_parse(text: str, bound: Bound) -> None:
    assert parse_bound(text) == bound


@pytest.mark.parametrize("text", ["12", "m", "m-1", "-3s", "3 m", "infs", "nans", "3ms", ""])
def test_malformed_bounds_say_how_to_write_one(text: str) -> None:
    with pytest.raises(WindowError, match=r"write seconds from the log's start as '12\.5s'"):
        parse_bound(text)


def test_process_keeps_the_movements_asked_for(small_log: Path, tmp_path: Path) -> None:
    out = tmp_path / "d.mcap"
    code, output = _run("process", str(small_log), "--from", "m1", "--to", "m1", "--out", str(out))
    assert code == 0, output
    times = _movement_times(small_log)
    assert all(times[(1, "start")] <= t <= times[(1, "end")] for topic, t, _ in _read(out))
    estimates = [m for topic, _, m in _read(out) if topic == "/pipeline/estimate"]
    assert [m["index"] for m in estimates] == [1]

    doc = _summary("process", str(small_log), "--from", "m1")
    assert [m["index"] for m in doc["movements"]] == [1, 2]
    assert doc["window"] == {"from": "m1"}


def test_process_by_seconds_from_the_first_message(small_log: Path) -> None:
    first = _read(small_log)[0][1]
    times = _movement_times(small_log)
    # up to movement 1's end keyframe, exactly: movements 0 and 1
    to_s = (times[(1, "end")] - first) / 1e9
    doc = _summary("process", str(small_log), "--to", f"{to_s}s")
    assert [(m["index"], m["status"]) for m in doc["movements"]] == [(0, "ok"), (1, "ok")]
    # a twentieth of a second earlier, movement 1 has lost its end keyframe
    doc = _summary("process", str(small_log), "--to", f"{to_s - 0.05}s")
    assert [(m["index"], m["status"]) for m in doc["movements"]] == [
        (0, "ok"),
        (1, "skipped: no end keyframe"),
    ]


def test_windows_the_log_lacks_are_one_line_errors(small_log: Path) -> None:
    code, output = _run("process", str(small_log), "--from", "m7")
    assert code == 1
    assert output == (
        f"Error: {small_log.name} has no start of movement 7 (it has movements m0 to m2)\n"
    )
    code, output = _run("process", str(small_log), "--from", "m2", "--to", "m1")
    assert (code, output) == (1, f"Error: {small_log.name}: --from m2 is not before --to m1\n")
    code, output = _run("replay", str(small_log), "--from", "4", "--save", "x.rrd")
    assert code == 2 and "'4' is not a bound" in output


@needs_viewer
def test_replay_takes_a_window(small_log: Path, tmp_path: Path) -> None:
    rrd = tmp_path / "w.rrd"
    code, output = _run("replay", str(small_log), "--from", "m2", "--save", str(rrd))
    assert code == 0, output
    assert f"{small_log}: 1/1 movements used" in output


def test_cat_prints_every_message_as_a_json_line(small_log: Path) -> None:
    code, output = _run("cat", str(small_log))
    assert code == 0, output
    lines = [json.loads(line) for line in output.splitlines()]
    expected = _read(small_log)
    assert [(d["topic"], d["log_time_ns"]) for d in lines] == [(t, lt) for t, lt, _ in expected]
    for doc, (topic, _, msg) in zip(lines, expected, strict=True):
        if topic == "/camera/panorama":
            size = len(base64.b64decode(msg["data"]))
            assert doc["message"] == {**msg, "data": f"<{size} bytes>"}
        else:
            assert doc["message"] == msg


def test_cat_topics_window_and_data(small_log: Path) -> None:
    code, output = _run(
        "cat", str(small_log), "--topic", "/camera/panorama", "--from", "m2", "--data"
    )
    assert code == 0, output
    start = _movement_times(small_log)[(2, "start")]
    expected = [m for topic, t, m in _read(small_log) if topic == "/camera/panorama" and t >= start]
    assert [json.loads(line)["message"] for line in output.splitlines()] == expected

    code, output = _run("cat", str(small_log), "--topic", "/robot/odometry")
    assert code == 1
    assert output.startswith(f"Error: {small_log.name} has no topic /robot/odometry; its topics: ")
    assert "/camera/panorama, /robot/movement, /sim/ground_truth" in output


def test_split_and_merge_give_the_log_back(small_log: Path, tmp_path: Path) -> None:
    log = tmp_path / "run.mcap"
    log.write_bytes(small_log.read_bytes())
    code, output = _run("split", str(log), "--at", "m1", "--at", "m2")
    assert code == 0, output
    parts = [tmp_path / f"run.part{k}.mcap" for k in (1, 2, 3)]
    times = _movement_times(log)
    edges = [None, times[(1, "start")], times[(2, "start")], None]
    whole = _read(log)
    for k, part in enumerate(parts):
        mine = [
            (topic, t, m) for topic, t, m in whole if (edges[k] or 0) <= t < (edges[k + 1] or 2**63)
        ]
        assert _read(part) == mine
        assert _metadata(part) == _metadata(log)
        assert [m["index"] for m in _summary("process", str(part))["movements"]] == [k]

    merged = tmp_path / "merged.mcap"
    code, output = _run("merge", *map(str, parts), "--out", str(merged))
    assert code == 0, output
    key = [(topic, t, json.dumps(m, sort_keys=True)) for topic, t, m in whole]
    assert Counter(key) == Counter(
        (topic, t, json.dumps(m, sort_keys=True)) for topic, t, m in _read(merged)
    )
    assert _metadata(merged) == _metadata(log)


def test_merge_a_log_with_its_derived_log(small_log: Path, tmp_path: Path) -> None:
    derived = tmp_path / "d.mcap"
    assert _run("process", str(small_log), "--out", str(derived))[0] == 0
    both = tmp_path / "both.mcap"
    code, output = _run("merge", str(small_log), str(derived), "--out", str(both))
    assert code == 0, output
    assert Counter(t for t, _, _ in _read(both)) == Counter(
        t for t, _, _ in _read(small_log) + _read(derived)
    )
    session = json.loads(_metadata(both)["bslam.session"]["json"])
    assert session["derived"] == json.loads(_metadata(derived)["bslam.session"]["json"])["derived"]


def test_merge_refuses_other_sessions_and_overlaps(small_log: Path, tmp_path: Path) -> None:
    other = write_log(tmp_path / "other.mcap", moves=MOVES[:1], doc=session_doc())
    code, output = _run("merge", str(small_log), str(other), "--out", str(tmp_path / "m.mcap"))
    assert code == 1 and "logs of different sessions cannot be merged" in output
    code, output = _run("merge", str(small_log), str(small_log), "--out", str(tmp_path / "m.mcap"))
    assert code == 1 and "over the same time" in output
    assert not (tmp_path / "m.mcap").exists()


def test_split_merge_and_recover_report_progress_per_message(
    small_log: Path, tmp_path: Path
) -> None:
    from data_schemas.mcap.parts import merge_logs, part_paths, split_log
    from data_schemas.mcap.recover import recover_log

    total = len(_read(small_log))
    ticks: list[int] = []
    outs = part_paths(small_log, 2, tmp_path)
    assert sum(split_log(small_log, [parse_bound("m1")], outs, progress=ticks.append)) == total
    assert ticks == [1] * total
    ticks.clear()
    assert merge_logs(outs, tmp_path / "m.mcap", progress=ticks.append) == total
    assert ticks == [1] * total
    done: list[int] = []
    recover_log(small_log, tmp_path / "r.mcap", progress=done.append)
    assert done == list(range(1, total + 1))
