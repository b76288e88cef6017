"""Landmarks that look alike: named by association (``blue#1``), what stays open reported per
movement and in the summary; coded landmarks go through the whole pipeline (real simulator,
``bslam simulate`` / ``process``)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
import rerun as rr
from click.testing import CliRunner
from logfactory import session_doc, write_log
from mcap.reader import make_reader
from test_rerun import _read

from data_schemas.codec import validate
from recorder.sim.scenario import builtin_scenario
from replay.cli import cli
from tests.mcap_reader import LogReader


def _scenario(tmp_path: Path) -> Path:
    doc = builtin_scenario("paper").to_dict()
    doc["landmarks"][3]["color"] = "blue"  # L4 now looks like L3
    doc["landmarks"].append(
        {"name": "L5", "x": 0.55, "y": 0.12, "bands": ["magenta", "yellow"], "radius": 0.01}
    )
    path = tmp_path / "alike.json"
    path.write_text(json.dumps(doc))
    return path


@pytest.fixture(scope="module")
def alike_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("alike")


@pytest.fixture(scope="module")
def alike(alike_folder: Path) -> tuple[dict[str, Any], str]:
    folder = alike_folder
    log = folder / "alike.mcap"
    sim = CliRunner().invoke(
        cli, ["simulate", "--scenario", str(_scenario(folder)), "--out", str(log), "--seed", "3"]
    )
    assert sim.exit_code == 0, sim.output
    summary = folder / "alike.summary.json"
    result = CliRunner().invoke(
        cli,
        ["process", str(log), "--summary", str(summary), "--out", str(folder / "derived.mcap")],
    )
    assert result.exit_code == 0, result.output
    return json.loads(summary.read_text()), result.output


def test_alike_landmarks_are_named_by_association(alike: tuple[dict[str, Any], str]) -> None:
    doc, output = alike
    assert doc["ambiguous_classes"] == {"blue": ["L3", "L4"]}
    # catalog names of a shared class are never used: the map says blue#1, blue#2
    assert "L3" not in doc["landmarks"] and "L4" not in doc["landmarks"]
    assoc = doc["association"]
    assert assoc["named"] == {"blue": ["blue#1", "blue#2"]}
    assert assoc["catalog_count"] == {"blue": 2}
    matched = assoc["matched_truth"]
    assert sorted(matched[n] for n in ("blue#1", "blue#2")) == ["L3", "L4"]
    errors = [doc["error_m"][n] for n in ("blue#1", "blue#2")]
    assert max(errors) <= 0.10 and sum(errors) / 2 <= 0.03
    for move in doc["movements"]:
        assert "L3" not in move["bearings_deg"] and "L4" not in move["bearings_deg"]
        assert set(move["landmarks"]) <= {"L5", "blue#1", "blue#2"}
    assert "alike landmarks named: blue 2/2" in output
    # every blob of the class at a keyframe is counted, and those given a name, then or later
    counts = assoc["detections"]["blue"]
    blobs = sum(
        b is not None
        for move in doc["movements"]
        for n, pair in move["bearings_deg"].items()
        if n.startswith("blue#")
        for b in pair
    ) + sum(len(r) for move in doc["movements"] for r in move.get("named_from", {}).values())
    assert counts["named"] == blobs
    assert 0.5 * counts["at_keyframes"] <= counts["named"] <= counts["at_keyframes"]
    share = round(100 * counts["named"] / counts["at_keyframes"])
    assert f"blue 2/2, {share} % of {counts['at_keyframes']} detections" in output


def test_what_association_leaves_open_is_reported(alike: tuple[dict[str, Any], str]) -> None:
    doc, output = alike
    first = doc["movements"][0]  # nothing is named yet: every blob is unexplained, and said so
    assert "explained by no named landmark" in first["ambiguous_landmarks"]["blue unexplained"]
    assert "2 at O1, 2 at O2" in first["ambiguous_landmarks"]["blue unexplained"]
    flagged = [m["index"] for m in doc["movements"] if m.get("ambiguous_landmarks")]
    assert doc["association"]["movements_with_unresolved"] == flagged
    assert f"({len(flagged)} movement(s) with ambiguities)" in output
    assert "unresolved (landmarks that look alike)" in output
    named = [n for m in doc["movements"] for n in m.get("named_landmarks", [])]
    assert named == ["blue#1", "blue#2"]  # each named once, in order


def test_derived_log_and_rerun_show_the_names(
    alike: tuple[dict[str, Any], str], alike_folder: Path
) -> None:
    with (alike_folder / "derived.mcap").open("rb") as f:
        text = b"".join(m.data for _, _, m in make_reader(f).iter_messages())
    assert b"blue#1" in text and b"blue#2" in text  # frames keep the catalog's per-class report
    rrd = alike_folder / "alike.rrd"
    result = CliRunner().invoke(
        cli, ["replay", str(alike_folder / "alike.mcap"), "--save", str(rrd), "--keyframes-only"]
    )
    assert result.exit_code == 0, result.output
    entities = {str(c.entity_path) for c in rr.chunk.RrdReader(rrd).stream()}
    for k in (1, 2):
        assert f"/map/ellipses/blue\\#{k}" in entities and f"/error/blue\\#{k}" in entities
    assert not any("L3" in e or "L4" in e for e in entities if e.startswith("/map/"))


def test_every_detection_with_the_final_map_in_summary_derived_log_and_rerun(
    alike: tuple[dict[str, Any], str], alike_folder: Path
) -> None:
    doc, output = alike
    final = doc["association"]["final_map"]["blue"]
    # every keyframe blob of the class, each with one status; more named than movement by
    # movement (the first movements' blobs, before any name, among them)
    assert final["detections"] == doc["association"]["detections"]["blue"]["at_keyframes"]
    statuses = ("named", "contested", "unexplained", "not placed")
    assert sum(final[k] for k in statuses) == final["detections"]
    assert final["named"] > doc["association"]["detections"]["blue"]["named"]
    assert sum(final["per_name"].values()) == final["named"]
    assert set(final["per_name"]) == {"blue#1", "blue#2"}
    share = round(100 * final["named"] / final["detections"])
    assert f"({share} % with the final map)" in output
    # the derived log holds each of them, valid against its schema, as the summary counts
    with LogReader(alike_folder / "derived.mcap") as reader:
        msgs = [m.decode() for m in reader.messages(["/pipeline/association"])]
    assert len(msgs) == 1
    validate("bslam.Association", msgs[0])
    rows = msgs[0]["detections"]
    assert len(rows) == final["detections"]
    for k in statuses:
        assert sum(r["status"] == k for r in rows) == final[k]
    assert all(("name" in r) == (r["status"] == "named") for r in rows)
    first = [r for r in rows if r["movement"] == 0]  # nothing was named then
    assert any(r["status"] == "named" for r in first)
    # Rerun's log says it
    rrd = alike_folder / "final.rrd"
    result = CliRunner().invoke(
        cli, ["replay", str(alike_folder / "alike.mcap"), "--save", str(rrd), "--keyframes-only"]
    )
    assert result.exit_code == 0, result.output
    texts = [t for r in _read(rrd)["/log"] for t in r.get("TextLog:text") or ()]
    want = f"with the final map, blue: {final['named']} of {final['detections']} detections named"
    assert any(t.startswith(want) for t in texts), texts


def test_coded_landmark_is_mapped_through_the_pipeline(alike: tuple[dict[str, Any], str]) -> None:
    doc, _ = alike
    assert "L5" in doc["landmarks"]
    assert doc["error_m"]["L5"] < 0.05
    assert all(move["bearings_deg"]["L5"] != [None, None] for move in doc["movements"][:3])


def test_a_log_whose_reference_shares_its_class_is_refused(tmp_path: Path) -> None:
    doc = session_doc()
    doc["landmarks"][2]["color"] = "red"  # L3 looks like the reference L1
    log = write_log(tmp_path / "shared.mcap", doc=doc)
    result = CliRunner().invoke(cli, ["process", str(log), "--summary", str(tmp_path / "s")])
    assert result.exit_code == 1
    lines = result.output.strip().splitlines()
    assert len(lines) == 1, result.output
    assert "reference landmark 'L1' shares its class 'red' with L3" in lines[0]


def test_the_paper_estimator_with_landmarks_that_look_alike_is_refused(tmp_path: Path) -> None:
    doc = session_doc()
    doc["landmarks"][3]["color"] = doc["landmarks"][2]["color"]  # L4 looks like L3
    log = write_log(tmp_path / "alike.mcap", doc=doc)
    result = CliRunner().invoke(
        cli, ["process", str(log), "--estimator", "paper", "--summary", str(tmp_path / "s")]
    )
    assert result.exit_code == 1
    lines = result.output.strip().splitlines()
    assert len(lines) == 1, result.output
    assert "associated with the joint estimator only" in lines[0]
    assert "use --estimator joint" in lines[0]
    assert not (tmp_path / "s").exists()
