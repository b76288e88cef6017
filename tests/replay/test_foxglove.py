"""Derived logs in Foxglove's well-known schemas: checked against the published schemas, read back
with the mcap library, and read by Foxglove's own MCAP reader and JSON-schema parser (Node).

Oracles: the JSON Schemas of the npm package ``@foxglove/schemas`` (read by Node, compared with
the vendored files), the jsonschema library, the other channels of the same log and the summary
(means, particles), the 80% region's Mahalanobis radius (chi-square, 2 dof: -2 ln 0.2), and
Foxglove's parser (``tests/foxglove_js/check_mcap.mjs``). The Node tests are slow (``npm install``
in ``tests/foxglove_js`` brings the pinned packages, ~190 MB on a fresh machine) and are skipped
only where Node is not installed.
"""

from __future__ import annotations

import base64
import fcntl
import json
import math
import shutil
import subprocess
from collections import defaultdict
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import pytest
from logfactory import MOVES
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from data_schemas.registry import TOPICS
from replay.process import process_log
from replay.records import MethodConfig

JS = Path(__file__).resolve().parents[1] / "foxglove_js"
VENDORED = Path(__file__).resolve().parents[2] / "data_schemas" / "foxglove"
#: the Foxglove channels of a derived log
FOXGLOVE_TOPICS = {
    name: t.schema
    for name, t in TOPICS.items()
    if name.startswith("/pipeline/") and t.schema.startswith("foxglove.")
}
CHI2_80_2DOF = -2.0 * math.log(0.2)


@pytest.fixture(scope="module")
def node() -> str:
    """Node, with the helper's pinned packages installed (``npm install``, once, under a lock)."""
    exe, npm = shutil.which("node"), shutil.which("npm")
    if exe is None or npm is None:
        pytest.skip("Node.js is not installed: Foxglove's own parser cannot run")
    with (JS / ".install.lock").open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (JS / "node_modules" / ".package-lock.json").exists():
            done = subprocess.run(
                [npm, "install", "--no-audit", "--no-fund", "--loglevel=error"],
                cwd=JS,
                capture_output=True,
                text=True,
                check=False,
            )
            assert done.returncode == 0, done.stderr
    return exe


@pytest.fixture(scope="module")
def derived(small_log: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("derived") / "d.mcap"
    process_log(small_log, MethodConfig(n_r=20, n_l=40), out=out, summary=out.with_suffix(".json"))
    return out


def _messages(log: Path) -> dict[str, list[dict[str, Any]]]:
    """Every message of ``log`` by topic, read with the mcap library, in log time order."""
    out: dict[str, list[dict[str, Any]]] = defaultdict(list)
    with log.open("rb") as f:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=True):
            out[channel.topic].append(json.loads(message.data))
    return out


def _published(node: str) -> dict[str, Any]:
    script = 'process.stdout.write(JSON.stringify(require("@foxglove/schemas/jsonschema")))'
    done = subprocess.run([node, "-e", script], cwd=JS, capture_output=True, check=True)
    schemas: dict[str, Any] = json.loads(done.stdout)
    return schemas


@pytest.mark.slow  # npm install of Foxglove's packages (~190 MB) on a fresh machine
def test_vendored_schemas_are_the_published_ones(node: str) -> None:
    published = _published(node)
    files = sorted(VENDORED.glob("foxglove.*.json"))
    assert {p.name for p in files} >= {f"{s}.json" for s in FOXGLOVE_TOPICS.values()}
    for path in files:
        name = path.name.removeprefix("foxglove.").removesuffix(".json")
        assert json.loads(path.read_text()) == published[name], path.name


def test_every_foxglove_message_is_valid_under_the_published_schema(derived: Path) -> None:
    messages = _messages(derived)
    assert set(FOXGLOVE_TOPICS) <= set(messages)
    for topic, schema in FOXGLOVE_TOPICS.items():
        document = json.loads((VENDORED / f"{schema}.json").read_text())
        validator = jsonschema.Draft7Validator(document)
        for msg in messages[topic]:
            validator.validate(msg)


def _yaw(q: dict[str, float]) -> float:
    assert q["x"] == q["y"] == 0.0
    assert math.hypot(q["z"], q["w"]) == pytest.approx(1.0)
    return 2.0 * math.atan2(q["z"], q["w"])


def test_map_poses_and_particles_carry_the_pipeline_results(derived: Path) -> None:
    messages = _messages(derived)
    summary = json.loads(derived.with_suffix(".json").read_text())
    final = messages["/pipeline/map"][-1]
    assert [(d["type"], d["id"]) for d in final["deletions"]] == [(1, "")]  # ALL
    by_id = {e["id"]: e for e in final["entities"]}
    assert set(by_id) == {f"landmark/{n}" for n in summary["landmarks"]}
    last = {lm["name"]: lm for lm in messages["/pipeline/estimate"][-1]["landmarks"]}
    assert set(last) == set(summary["landmarks"])
    for name, landmark in last.items():
        entity = by_id[f"landmark/{name}"]
        assert entity["frame_id"] == "fl"
        (sphere,) = entity["spheres"]
        p = sphere["pose"]["position"]
        assert [p["x"], p["y"]] == pytest.approx(landmark["mean"], abs=1e-9)
        assert entity["texts"][0]["text"] == name
        # the outline is the 80% region: every point at Mahalanobis radius^2 = -2 ln 0.2
        c = landmark["cov"]
        cov = np.array([[c["xx"], c["xy"]], [c["xy"], c["yy"]]])
        d = np.array([[q["x"], q["y"]] for q in entity["lines"][0]["points"]]) - landmark["mean"]
        r2 = np.einsum("ij,jk,ik->i", d, np.linalg.inv(cov), d)
        assert r2 == pytest.approx(CHI2_80_2DOF, rel=1e-6)

    estimates = [e for e in messages["/pipeline/estimate"] if "observation_points" in e]
    keyframes = messages["/pipeline/keyframe_poses"]
    assert len(keyframes) == len(estimates) == len(MOVES)
    for est, kf, tf in zip(estimates, keyframes, messages["/pipeline/tf"], strict=True):
        o1, o2 = est["observation_points"]["o1"], est["observation_points"]["o2"]
        heading = math.atan2(o2[1] - o1[1], o2[0] - o1[0])
        for pose, at in zip(kf["poses"], (o1, o2), strict=True):
            assert [pose["position"]["x"], pose["position"]["y"]] == pytest.approx(at)
            assert _yaw(pose["orientation"]) == pytest.approx(heading)
        assert (tf["parent_frame_id"], tf["child_frame_id"]) == ("fl", "robot")
        assert [tf["translation"]["x"], tf["translation"]["y"]] == pytest.approx(o2)
        assert _yaw(tf["rotation"]) == pytest.approx(heading)
    trajectory = messages["/pipeline/trajectory"][-1]["poses"]
    assert trajectory == [p for kf in keyframes for p in kf["poses"]]

    clouds = messages["/pipeline/particles"]
    sets = [m for m in messages["/pipeline/particles_fl"] if m["landmarks"]]
    assert len(clouds) == len(sets) > 0
    for cloud, fl in zip(clouds, sets, strict=True):
        fields = {f["name"]: f for f in cloud["fields"]}
        assert all(f["type"] == 7 for f in fields.values())  # FLOAT32
        raw = np.frombuffer(base64.b64decode(cloud["data"]), np.uint8)
        rows = raw.reshape(-1, cloud["point_stride"])
        column = {
            n: rows[:, f["offset"] : f["offset"] + 4].copy().view("<f4")[:, 0]
            for n, f in fields.items()
        }
        for k, s in enumerate(fl["landmarks"]):
            mine = column["landmark"] == k
            assert column["x"][mine] == pytest.approx(np.float32(s["x"]))
            assert column["y"][mine] == pytest.approx(np.float32(s["y"]))
        assert not column["z"].any()


def _check(node: str, log: Path) -> dict[str, Any]:
    done = subprocess.run(
        [node, str(JS / "check_mcap.mjs"), str(log)], capture_output=True, text=True, check=False
    )
    assert done.returncode == 0, done.stderr
    report: dict[str, Any] = json.loads(done.stdout)["topics"]
    return report


@pytest.mark.slow  # npm install of Foxglove's packages (~190 MB) on a fresh machine
def test_foxglove_parser_reads_every_channel_of_a_derived_log(node: str, derived: Path) -> None:
    report = _check(node, derived)
    counts = {t: len(m) for t, m in _messages(derived).items()}
    assert {t: e["messages"] for t, e in report.items()} == counts
    assert {t: e["problems"] for t, e in report.items()} == {t: [] for t in counts}
    assert {report[t]["schema"] for t in FOXGLOVE_TOPICS} == set(FOXGLOVE_TOPICS.values())
    assert report["/pipeline/particles"]["first"]["data"]["bytes"] > 0  # base64 made bytes


@pytest.mark.slow  # npm install of Foxglove's packages (~190 MB) on a fresh machine
def test_foxglove_parser_check_refuses_what_foxglove_cannot_read(node: str, tmp_path: Path) -> None:
    """The helper can fail: a nullable field, and a message whose field has the wrong type."""
    log = tmp_path / "bad.mcap"
    nullable = {"type": "object", "properties": {"a": {"type": ["number", "null"]}}}
    plain = {"type": "object", "properties": {"a": {"type": "number"}}}
    with log.open("wb") as f:
        writer = Writer(f, compression=CompressionType.NONE)
        writer.start()
        channels = (("/nullable", nullable, {"a": 1}), ("/typed", plain, {"a": "x"}))
        for topic, schema, msg in channels:
            sid = writer.register_schema(topic[1:], "jsonschema", json.dumps(schema).encode())
            cid = writer.register_channel(topic, "json", sid)
            writer.add_message(cid, 0, json.dumps(msg).encode(), 0)
        writer.finish()
    report = _check(node, log)
    assert report["/nullable"]["problems"] == ['schema: Unsupported type ["number","null"] for a']
    assert report["/typed"]["problems"] == ["a: expected a number"]
