"""``bslam process``: summary contract, derived log, skipped movements, many logs."""

from __future__ import annotations

import gc
import json
import math
import os
import subprocess
import sys
import weakref
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner
from logfactory import MOVES, write_log
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
from viewer import needs_experiments

from data_schemas.codec import validate_message
from replay.batch import LogJob, expand_logs, plan_jobs, process_job
from replay.cli import cli
from replay.parallel import SchedulerError, run_tasks
from replay.process import process_log
from replay.records import MethodConfig
from replay.sinks.summary import SummarySink
from replay.stages import run_log


def _check_contract(doc: dict[str, Any], n_movements: int) -> None:
    assert doc["frame"] == {"origin": "L1", "x_axis": "L2"}
    assert set(doc["method"]) >= {"prior", "n_r", "n_l", "vision_error_deg"}
    assert [m["index"] for m in doc["movements"]] == list(range(n_movements))
    for m in doc["movements"]:
        assert m["status"] == "ok" or m["status"].startswith("skipped: ")
        for pair in m["bearings_deg"].values():
            assert len(pair) == 2
            assert all(b is None or -180.0 <= b < 180.0 for b in pair)
        for est in m["landmarks"].values():
            assert len(est["mean"]) == 2
            cov = est["cov"]
            assert cov[0][1] == cov[1][0] and cov[0][0] > 0 and cov[1][1] > 0
    assert "L1" not in doc["landmarks"] and "L2" not in doc["landmarks"]


def test_summary_matches_contract_and_truth(small_log: Path, tmp_path: Path) -> None:
    out = tmp_path / "s.json"
    result = CliRunner().invoke(cli, ["process", str(small_log), "--summary", str(out)])
    assert result.exit_code == 0, result.output
    doc = json.loads(out.read_text())
    _check_contract(doc, len(MOVES))
    assert set(doc["landmarks"]) == {"L3", "L4"}
    # the bearings used are the painted ones (bars are 5 px of a 1 deg/px panorama)
    (x, y, h), _ = MOVES[0]
    true_l4 = math.degrees(math.atan2(0.18 - y, 0.85 - x) - h)
    assert doc["movements"][0]["bearings_deg"]["L4"][0] == pytest.approx(true_l4, abs=1.0)
    # the final map is near the truth mapped to FL (a few cm at |L1 L2| = 0.3 m)
    for name, est in doc["landmarks"].items():
        truth = doc["truth"]["landmarks"][name]
        err_m = math.dist(est["mean"], truth) * doc["truth"]["unit_m"]
        assert err_m == pytest.approx(doc["error_m"][name], abs=1e-6)
    assert doc["mean_error_m"] < 0.05


def test_stdout_summary_is_the_same_document(small_log: Path, tmp_path: Path) -> None:
    result = CliRunner().invoke(cli, ["process", str(small_log), "--seed", "3"])
    assert result.exit_code == 0
    again = process_log(small_log, MethodConfig(seed=3)).to_json()
    assert json.loads(result.output) == json.loads(json.dumps(again))


def test_seed_changes_particles_not_contract(small_log: Path) -> None:
    a = process_log(small_log, MethodConfig(seed=1, estimator="paper")).to_json()
    b = process_log(small_log, MethodConfig(seed=2, estimator="paper")).to_json()
    assert a["landmarks"]["L4"]["mean"] != b["landmarks"]["L4"]["mean"]
    assert process_log(small_log, MethodConfig(seed=1, estimator="paper")).to_json() == a


def test_joint_map_does_not_depend_on_the_initializer_seed(small_log: Path) -> None:
    # the particles only initialize; the joint map is the optimum of the same bearings
    a = process_log(small_log, MethodConfig(seed=1)).to_json()
    b = process_log(small_log, MethodConfig(seed=2)).to_json()
    assert a["method"]["estimator"] == "joint"
    for name, est in a["landmarks"].items():
        assert est["mean"] == pytest.approx(b["landmarks"][name]["mean"], abs=1e-6)


def test_reference_hidden_joint_places_movement_by_resection(tmp_path: Path) -> None:
    log = write_log(tmp_path / "hidden.mcap", hidden=lambda i, ph: ("L1",) if i == 1 else ())
    doc = process_log(log, MethodConfig()).to_json()
    moves = doc["movements"]
    assert [m["status"] for m in moves] == ["ok"] * len(moves)
    assert moves[1]["placement"] == "resection"
    assert moves[0]["placement"] == moves[2]["placement"] == "reference pair"
    assert "L1" not in moves[1]["residuals_deg"]
    assert set(moves[1]["residuals_deg"]) == {"L2", "L3", "L4"}


def test_reference_hidden_skips_movement_and_goes_on(tmp_path: Path) -> None:
    log = write_log(tmp_path / "hidden.mcap", hidden=lambda i, ph: ("L1",) if i == 1 else ())
    doc = process_log(log, MethodConfig(estimator="paper")).to_json()
    statuses = [m["status"] for m in doc["movements"]]
    assert statuses[0] == "ok" and statuses[2] == "ok"
    assert statuses[1].startswith("skipped: ") and "L1" in statuses[1]
    assert doc["movements"][1]["bearings_deg"]["L1"] == [None, None]
    # a skipped movement leaves the belief as it was
    assert doc["movements"][1]["landmarks"] == doc["movements"][0]["landmarks"]


def test_occluded_landmark_is_reported_not_used(tmp_path: Path) -> None:
    log = write_log(tmp_path / "occl.mcap", hidden=lambda i, ph: ("L4",) if ph == "end" else ())
    doc = process_log(log, MethodConfig(estimator="paper")).to_json()
    assert all(m["status"] == "ok" for m in doc["movements"])
    assert "L4" not in doc["landmarks"]
    assert all("L4" in m["skipped_landmarks"] for m in doc["movements"])
    assert all(m["bearings_deg"]["L4"][1] is None for m in doc["movements"])


def test_two_frames_at_one_time_stamp_are_two_keyframes(tmp_path: Path) -> None:
    # movement 1 starts at the tick movement 0 ended (a turn too short to take a tick): its
    # start frame shares the end frame's time stamp and comes after movement 0 has run
    method = MethodConfig(n_l=150, seed=7)
    plain = process_log(write_log(tmp_path / "plain.mcap"), method).to_json()
    log = write_log(tmp_path / "instant.mcap", instant={1})
    doc = process_log(log, method).to_json()
    assert [m["status"] for m in doc["movements"]] == ["ok"] * len(MOVES)
    for got, want in zip(doc["movements"], plain["movements"], strict=True):
        assert got["bearings_deg"] == want["bearings_deg"]  # each keyframe its own frame
    start_1 = doc["movements"][1]["bearings_deg"]["L1"][0]
    assert start_1 != doc["movements"][0]["bearings_deg"]["L1"][1]


def test_joint_maps_a_landmark_seen_only_at_single_keyframes(tmp_path: Path) -> None:
    # L4 is never seen at both ends of a movement: the paper cannot use it, the joint map can
    log = write_log(tmp_path / "occl.mcap", hidden=lambda i, ph: ("L4",) if ph == "end" else ())
    # lengths free: this fixture's movements start up to 2.5 cm from where the last one ended,
    # which the turn-in-place link does not allow; with every length held to its exact distance
    # too, that misfit lands on L4 (measured 5.6 cm with the default distance prior, 3.8 without)
    doc = process_log(log, MethodConfig(distance_prior=None)).to_json()
    assert "L4" in doc["landmarks"]
    assert doc["error_m"]["L4"] < 0.05
    assert all(m["residuals_deg"].get("L4", [None, None])[1] is None for m in doc["movements"])


def test_derived_log_channels_validate(small_log: Path, tmp_path: Path) -> None:
    out = tmp_path / "d.mcap"
    doc = process_log(small_log, MethodConfig(n_r=20, n_l=40), out=out).to_json()
    counts: dict[str, int] = {}
    particle_sets = 0
    with out.open("rb") as f:
        reader = make_reader(f)
        for _, channel, message in reader.iter_messages(log_time_order=True):
            msg = json.loads(message.data)
            validate_message(channel.topic, msg)
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.topic == "/pipeline/estimate" and msg["index"] == len(MOVES) - 1:
                final = {lm["name"]: lm["mean"] for lm in msg["landmarks"]}
            if channel.topic == "/pipeline/particles_fr":
                assert all(len(s["x"]) == 20 for s in msg["landmarks"])
            if channel.topic == "/pipeline/particles_fl" and msg["landmarks"]:
                particle_sets += 1  # a point cloud of the Foxglove channels each
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
    assert counts == {
        "/pipeline/bearings": 2 * len(MOVES),
        "/pipeline/particles_fr": len(MOVES),
        "/pipeline/particles_fl": len(MOVES),
        "/pipeline/estimate": len(MOVES),
        "/pipeline/map": len(MOVES),
        "/pipeline/keyframe_poses": len(MOVES),
        "/pipeline/trajectory": len(MOVES),
        "/pipeline/tf": len(MOVES),
        "/pipeline/particles": particle_sets,
    }
    for name, mean in final.items():
        assert mean == pytest.approx(doc["landmarks"][name]["mean"], abs=1e-8)
    assert json.loads(meta["bslam.session"]["json"])["derived"]["source"] == small_log.name


def _rewritten_by_mcap(log: Path, out: Path) -> Path:
    """``log`` rewritten by mcap's own writer: small zstd chunks, so read by mcap's reader."""
    with log.open("rb") as src, out.open("wb") as dst:
        reader = make_reader(src)
        writer = Writer(dst, chunk_size=32 * 1024, compression=CompressionType.ZSTD)
        writer.start()
        for record in reader.iter_metadata():
            writer.add_metadata(record.name, record.metadata)
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            assert schema is not None
            if schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(
                    schema.name, schema.encoding, schema.data
                )
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schemas[schema.id], channel.metadata
                )
            writer.add_message(
                channels[channel.id],
                message.log_time,
                message.data,
                message.publish_time,
                message.sequence,
            )
        writer.finish()
    return out


def test_log_of_another_writer_gives_the_same_results(small_log: Path, tmp_path: Path) -> None:
    """Stored chunks (the recorder's) or zstd chunks (mcap's Writer): same outputs."""
    other = _rewritten_by_mcap(small_log, tmp_path / "zstd.mcap")
    for path, compression in ((small_log, ""), (other, "zstd")):
        with path.open("rb") as f:
            summary = make_reader(f).get_summary()
            assert summary is not None
            assert {c.compression for c in summary.chunk_indexes} == {compression}
    method = MethodConfig(n_r=20, n_l=40)
    ours = process_log(small_log, method, out=tmp_path / "a.mcap").to_json()
    theirs = process_log(other, method, out=tmp_path / "b.mcap").to_json()
    assert theirs == {**ours, "log": other.name}
    derived = []
    for path in (tmp_path / "a.mcap", tmp_path / "b.mcap"):
        with path.open("rb") as f:
            derived.append(
                [(c.topic, m.log_time, m.data) for _, c, m in make_reader(f).iter_messages()]
            )
    assert derived[0] == derived[1]


def _hide_all_at_end_of_movement_1(i: int, phase: str) -> tuple[str, ...]:
    # nothing seen at O2: neither the paper's filter nor the joint map can place movement 1
    return ("L1", "L2", "L3", "L4") if (i, phase) == (1, "end") else ()


QUIET_RUN = """
import sys
from replay.process import process_log
from replay.records import MethodConfig
doc = process_log(sys.argv[1], MethodConfig()).to_json()
print(doc["movements"][1]["status"])
"""


def test_library_prints_nothing_for_skips(tmp_path: Path) -> None:
    """As in an experiment run or a pool worker: no logging configured, nothing on stderr."""
    log = write_log(tmp_path / "quiet.mcap", hidden=_hide_all_at_end_of_movement_1)
    root = Path(__file__).resolve().parents[2]
    done = subprocess.run(
        [sys.executable, "-c", QUIET_RUN, str(log)],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, "PYTHONPATH": str(root)},
    )
    assert done.stdout.startswith("skipped: ")
    assert done.stderr == ""


def test_one_log_reports_each_skipped_movement(tmp_path: Path) -> None:
    log = write_log(tmp_path / "hidden.mcap", hidden=_hide_all_at_end_of_movement_1)
    result = CliRunner().invoke(cli, ["process", str(log), "--summary", str(tmp_path / "s.json")])
    assert result.exit_code == 0, result.output
    warnings = [line for line in result.output.splitlines() if line.startswith("warning: ")]
    assert len(warnings) == 1 and "hidden.mcap: movement 1 skipped: " in warnings[0]


def test_many_logs_one_bad_one_line_each(tmp_path: Path) -> None:
    folder = tmp_path / "many"
    folder.mkdir()
    for i in range(2):
        write_log(folder / f"run{i}.mcap", hidden=_hide_all_at_end_of_movement_1)
    (folder / "broken.mcap").write_text("not a log")
    result = CliRunner().invoke(
        cli, ["process", str(folder), "--summary", str(tmp_path / "sums"), "--workers", "2"]
    )
    assert result.exit_code == 1
    lines = [line for line in result.output.splitlines() if ".mcap: " in line]
    assert len(lines) == 3, result.output  # one line per log, no per-movement warnings
    assert "warning" not in result.output
    broken = next(line for line in lines if "broken.mcap" in line)
    assert "broken.mcap: FAILED: " in broken and "not an MCAP file" in broken
    assert sum(f"2/{len(MOVES)} movements used" in line for line in lines) == 2
    assert "1 of 3 logs failed" in result.output
    assert sorted(p.name for p in (tmp_path / "sums").iterdir()) == [
        "run0.summary.json",
        "run1.summary.json",
    ]


def test_dask_local_cluster_gives_same_results(tmp_path: Path) -> None:
    distributed = pytest.importorskip("distributed")
    logs = [write_log(tmp_path / f"d{i}.mcap") for i in range(2)]
    jobs = plan_jobs(expand_logs([str(tmp_path / "d*.mcap")]), None, None, MethodConfig())
    assert [j.log for j in jobs] == logs
    local = [o.value for o in run_tasks(process_job, jobs, progress=False)]
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None
    ) as cluster:
        remote = run_tasks(process_job, jobs, scheduler=cluster.scheduler_address, progress=False)
    assert all(o.ok for o in remote)
    assert [o.value for o in remote] == local


@needs_experiments
def test_unreachable_scheduler_is_one_line(tmp_path: Path) -> None:
    jobs = plan_jobs([write_log(tmp_path / "u.mcap")], None, None, MethodConfig())
    with pytest.raises(SchedulerError, match=r"^cannot reach the Dask scheduler at tcp://127"):
        run_tasks(process_job, jobs, scheduler="tcp://127.0.0.1:9", connect_timeout="1s")


def test_job_is_picklable() -> None:
    import pickle

    job = LogJob(Path("a.mcap"), None, None, MethodConfig(prior="mixture"))
    assert pickle.loads(pickle.dumps(job)) == job


def test_joint_places_a_waiting_movement_later(tmp_path: Path) -> None:
    # L1 hidden at the end of movement 0: no frame to start the map from; movement 1 starts it
    # and movement 0 is placed then (summary and derived log say so)
    log = write_log(
        tmp_path / "wait.mcap", hidden=lambda i, ph: ("L1",) if (i, ph) == (0, "end") else ()
    )
    out = tmp_path / "wait.derived.mcap"
    doc = process_log(log, MethodConfig(n_r=20, n_l=40), out=out).to_json()
    moves = doc["movements"]
    assert moves[0]["status"].startswith("skipped: no movement sees the reference pair")
    assert moves[1]["status"] == "ok" and moves[1]["also_placed"] == [0]
    with out.open("rb") as f:
        estimates = [
            json.loads(m.data)
            for _, c, m in make_reader(f).iter_messages()
            if c.topic == "/pipeline/estimate"
        ]
    assert estimates[1]["also_placed"] == [0] and "also_placed" not in estimates[0]
    assert all(e["estimator"] == "joint" for e in estimates)


def test_the_typed_summary_agrees_with_its_document(small_log: Path) -> None:
    import pickle

    result = process_log(small_log, MethodConfig())
    doc = result.to_json()
    moves = doc["movements"]
    assert result.movements == len(moves) == len(MOVES)
    assert result.used == sum(m["status"] == "ok" for m in moves) >= 2
    assert result.resected == sum(m.get("placement") == "resection" for m in moves)
    assert result.reference == (doc["frame"]["origin"], doc["frame"]["x_axis"])
    assert result.landmarks == len(doc["landmarks"]) > 0
    assert result.bearing_noise_deg == doc["bearing_noise_deg"]
    assert result.mean_error_m == doc.get("mean_error_m")
    assert result.untrusted == tuple(doc["trust"].get("reasons", ()))
    assert result.association is None and "association" not in doc
    # plain data: it comes back whole from a worker process (a pool, Dask)
    assert pickle.loads(pickle.dumps(result)) == result


def test_a_run_hands_every_object_back_to_the_garbage_collector(small_log: Path) -> None:
    """``run_log`` freezes the heap for the run only: a cycle dropped after it is collected."""

    class Node:
        other: object = None

    first, second = Node(), Node()
    first.other, second.other = second, first  # a cycle: only the collector frees it
    alive = weakref.ref(first)
    frozen_before = gc.get_freeze_count()
    sink = SummarySink()
    run_log(small_log, MethodConfig(), [sink])
    assert sink.document["movements"], "the run did not happen"
    assert gc.get_freeze_count() == frozen_before
    del first, second
    gc.collect()
    assert alive() is None


_EXIT_SCRIPT = """
import sys


class Noisy:
    def __del__(self):
        sys.stdout.write("finalized at exit")


kept = Noisy()
kept.me = kept  # a cycle, alive until the interpreter tears __main__ down
if sys.argv[1] == "cli":
    from replay.cli import main

    sys.argv = ["bslam", "process", sys.argv[2], "--summary", sys.argv[3]]
    main()
else:
    from replay.process import process_log
    from replay.records import MethodConfig

    process_log(sys.argv[2], MethodConfig())
"""


def test_bslam_skips_the_last_collection_at_exit_and_the_library_does_not(
    small_log: Path, tmp_path: Path
) -> None:
    """``bslam`` freezes its heap at exit: Python's final collection, which would walk every
    object only to free memory the system takes back, finds nothing to do, so a reference cycle
    alive at exit is not finalized. A program that calls the library keeps Python's exit."""
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    outputs = {}
    for mode in ("cli", "library"):
        done = subprocess.run(
            [sys.executable, "-c", _EXIT_SCRIPT, mode, str(small_log), str(tmp_path / "s.json")],
            env=env,
            capture_output=True,
            text=True,
            check=True,
        )
        outputs[mode] = done.stdout
    assert "movements used" in outputs["cli"]  # the command ran, then left without the walk
    assert "finalized at exit" not in outputs["cli"]
    assert outputs["library"] == "finalized at exit"
