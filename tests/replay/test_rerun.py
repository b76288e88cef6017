"""``bslam replay``: read the .rrd back with Rerun's own reader and check every stage."""

from __future__ import annotations

import base64
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pytest
import rerun as rr
from click.testing import CliRunner
from logfactory import HEIGHT, MOVES, write_log

from data_schemas.calibration import OmniCalibration, PinholeCalibration, UnwrappedCalibration
from replay.cli import cli
from replay.process import process_log
from replay.records import MethodConfig
from replay.sinks.rerun_sink import class_labels, detection_strips
from tests.mcap_reader import LogReader

ROOT = Path(__file__).resolve().parents[2]


def _read(rrd: Path) -> dict[str, list[dict[str, Any]]]:
    """entity path -> rows (column name -> value) of every chunk, static and temporal."""
    rows: dict[str, list[dict[str, Any]]] = {}
    for chunk in rr.chunk.RrdReader(rrd).stream():
        batch = chunk.to_record_batch()
        columns = [
            col.cast(pa.int64()) if pa.types.is_timestamp(col.type) else col
            for col in batch.columns
        ]
        table = pa.RecordBatch.from_arrays(columns, names=batch.schema.names).to_pylist()
        rows.setdefault(chunk.entity_path, []).extend(table)
    return rows


@pytest.fixture(scope="module")
def replayed(
    small_log: Path, tmp_path_factory: pytest.TempPathFactory
) -> tuple[Path, dict[str, Any]]:
    rrd = tmp_path_factory.mktemp("rrd") / "small.rrd"
    result = CliRunner().invoke(cli, ["replay", str(small_log), "--save", str(rrd), "--n-l", "100"])
    assert result.exit_code == 0, result.output
    assert f"rerun {rrd}" in result.output
    return rrd, process_log(small_log, MethodConfig(n_l=100)).to_json()


def _column(rows: list[dict[str, Any]], name: str) -> list[Any]:
    return [r[name] for r in rows if r.get(name) is not None]


def test_every_stage_is_an_entity(replayed: tuple[Path, dict[str, Any]]) -> None:
    rows = _read(replayed[0])
    for entity in [
        "/camera/panorama",
        "/camera/panorama/masks",
        "/camera/panorama/detections",
        "/bearings/L3",
        "/fr/cones/L4",
        "/fr/particles/L4",
        "/map/particles/L4",
        "/map/estimates",
        "/map/ellipses/L4",
        "/map/trajectory",
        "/map/truth/landmarks",
        "/map/truth/trajectory",
        "/error/mean",
        "/fig1/density/impartial",
        "/fig1/density/gaussian",
        "/fig1/density/mixture",
        "/fig1/range/impartial",
    ]:
        assert entity in rows, entity


def test_frames_and_masks(replayed: tuple[Path, dict[str, Any]]) -> None:
    rows = _read(replayed[0])
    n_frames = 4 * len(MOVES)  # two keyframes and two frames between per movement
    assert len(_column(rows["/camera/panorama"], "EncodedImage:blob")) == n_frames
    masks = _column(rows["/camera/panorama/masks"], "SegmentationImage:buffer")
    assert len(masks) == n_frames
    classes = set(np.concatenate([np.asarray(m[0], np.uint8) for m in masks]).tolist())
    assert classes == {0, 1, 2, 3, 4}  # background and the four landmarks


def test_detections_mark_every_bearing(replayed: tuple[Path, dict[str, Any]]) -> None:
    rrd, doc = replayed
    rows = [r for r in _read(rrd)["/camera/panorama/detections"] if "LineStrips2D:strips" in r]
    assert len(rows) == 4 * len(MOVES)
    for r in rows:
        assert len(r["LineStrips2D:labels"]) == len(r["LineStrips2D:strips"]) == 4
        for strip in r["LineStrips2D:strips"]:  # a vertical line across the unwrapped panorama
            (u0, v0), (u1, v1) = strip
            assert u0 == u1 and v0 == 0.0 and v1 == HEIGHT
    labelled = sorted(
        float(label.split()[1].rstrip("°"))
        for r in rows
        if r.get("movement") is not None
        for label in r["LineStrips2D:labels"]
        if label.startswith("L4 ")
    )
    used = sorted(b for m in doc["movements"] for b in m["bearings_deg"]["L4"])
    assert labelled == pytest.approx(used, abs=0.051)


def test_bearings_are_the_summary_bearings(replayed: tuple[Path, dict[str, Any]]) -> None:
    rrd, doc = replayed
    rows = _read(rrd)
    keyframe_rows = [r for r in rows["/bearings/L4"] if r.get("movement") is not None]
    logged = sorted(r["Scalars:scalars"][0] for r in keyframe_rows)
    used = sorted(b for m in doc["movements"] for b in m["bearings_deg"]["L4"])
    assert logged == pytest.approx(used, abs=1e-6)


def test_fr_particles_and_map_values(replayed: tuple[Path, dict[str, Any]]) -> None:
    rrd, doc = replayed
    rows = _read(rrd)
    # the joint estimator (the default) runs the paper's filter as its initializer: L4's
    # particles are drawn in its first movement, where it enters the map, then cleared
    fr = _column(rows["/fr/particles/L4"], "Points2D:positions")
    assert len(fr) == 1 and len(fr[0]) == 50
    fl = _column(rows["/map/particles/L4"], "Points2D:positions")
    assert len(fl) == 1 and len(fl[0]) == 100
    for path in ("/fr/particles/L4", "/map/particles/L4"):
        cleared = [r["movement"] for r in rows[path] if r.get("Clear:is_recursive") is not None]
        assert cleared == list(range(1, len(MOVES))), path
    est = next(r for r in rows["/map/estimates"] if r.get("movement") == len(MOVES) - 1)
    logged = dict(zip(est["Points2D:labels"], est["Points2D:positions"], strict=True))
    for name, e in doc["landmarks"].items():
        assert logged[name] == pytest.approx(e["mean"], abs=1e-5)  # float32 in Rerun
    errors = [r["Scalars:scalars"][0] for r in rows["/error/mean"] if r.get("Scalars:scalars")]
    assert errors[-1] == pytest.approx(doc["mean_error_m"], abs=1e-6)


def test_fl_is_drawn_y_up(replayed: tuple[Path, dict[str, Any]]) -> None:
    rows = _read(replayed[0])
    for root in ("/map", "/fr"):
        mat = _column(rows[root], "Transform3D:mat3x3")[0][0]
        assert mat[4] == -1.0 and mat[0] == 1.0 and mat[8] == 1.0


def test_fig1_range_marginal_is_flat_only_for_impartial(
    replayed: tuple[Path, dict[str, Any]],
) -> None:
    rows = _read(replayed[0])

    def spread(prior: str) -> float:
        values = np.asarray(
            _column(rows[f"/fig1/range/{prior}"], "BarChart:values")[0][0]["buffer"]
        )
        return float(np.std(values) / np.mean(values))

    assert spread("impartial") < 0.05
    assert spread("gaussian") > 0.3 and spread("mixture") > 0.3


def test_blueprint_is_stored(replayed: tuple[Path, dict[str, Any]]) -> None:
    reader = rr.chunk.RrdReader(replayed[0])
    [recording] = reader.recordings()
    [blueprint] = reader.blueprints()
    assert blueprint.application_id == recording.application_id == "bearing-slam"
    fields: dict[str, dict[str, Any]] = {}
    for chunk in reader.stream(store=blueprint):
        batch = chunk.to_record_batch()
        for name in batch.schema.names:
            if ":" in name:
                [value] = batch.column(name).to_pylist()
                fields.setdefault(chunk.entity_path, {})[name] = value[0]
    views = {
        (f["ViewBlueprint:space_origin"], f["ViewBlueprint:class_identifier"])
        for f in fields.values()
        if "ViewBlueprint:space_origin" in f
    }
    assert views == {
        ("/camera", "2D"),
        ("/bearings", "TimeSeries"),
        ("/", "2D"),  # FR and FL, each with its own contents
        ("/log", "TextLog"),
        ("/residuals", "TimeSeries"),
        ("/error", "TimeSeries"),
        ("/fig1/density/impartial", "2D"),
        ("/fig1/density/gaussian", "2D"),
        ("/fig1/density/mixture", "2D"),
        ("/fig1/range", "BarChart"),
    }
    tabs = {f.get("ContainerBlueprint:display_name") for f in fields.values()}
    assert {"Method", "Fig. 1"} <= tabs
    # every view shows something the recording holds, on the recording's movement timeline
    entities = set(_read(replayed[0]))
    for origin, _ in views:
        assert any(e == origin or e.startswith(origin.rstrip("/") + "/") for e in entities), origin
    assert fields["/time_panel"]["TimePanelBlueprint:timeline"] == "movement"


def test_keyframes_only_still_shows_the_keyframes(small_log: Path, tmp_path: Path) -> None:
    rrd = tmp_path / "keys.rrd"
    args = ["replay", str(small_log), "--save", str(rrd), "--keyframes-only", "--n-l", "100"]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    rows = _read(rrd)
    assert len(_column(rows["/camera/panorama"], "EncodedImage:blob")) == 2 * len(MOVES)
    assert len(_column(rows["/camera/panorama/masks"], "SegmentationImage:buffer")) == 2 * len(
        MOVES
    )


def test_recording_id_is_the_session_id(tmp_path: Path) -> None:
    ids = []
    for folder in ("a", "b"):  # two sessions, the same file name
        (tmp_path / folder).mkdir()
        log = write_log(tmp_path / folder / "demo.mcap")
        rrd = tmp_path / folder / "demo.rrd"
        result = CliRunner().invoke(cli, ["replay", str(log), "--save", str(rrd), "--n-l", "50"])
        assert result.exit_code == 0, result.output
        [entry] = rr.chunk.RrdReader(rrd).recordings()
        with LogReader(log) as reader:
            assert entry.recording_id == reader.session().session_id
        ids.append(entry.recording_id)
    assert ids[0] != ids[1]


def test_joint_residuals_noise_and_estimator_are_shown(
    replayed: tuple[Path, dict[str, Any]],
) -> None:
    rrd, doc = replayed
    rows = _read(rrd)
    noise = [
        r["Scalars:scalars"][0] for r in rows["/residuals/noise_deg"] if r.get("Scalars:scalars")
    ]
    assert noise[-1] == pytest.approx(doc["bearing_noise_deg"], abs=1e-4)
    rms = [r["Scalars:scalars"][0] for r in rows["/residuals/rms_deg"] if r.get("Scalars:scalars")]
    last = [
        x for pair in doc["movements"][-1]["residuals_deg"].values() for x in pair if x is not None
    ]
    assert rms[-1] == pytest.approx(math.sqrt(sum(x * x for x in last) / len(last)), abs=1e-4)
    texts = " ".join(str(t) for r in rows["/log"] for t in (r.get("TextLog:text") or []))
    assert "map made by the joint estimator" in texts
    assert "placed by reference pair" in texts


def test_rejected_blobs_are_shown_with_the_reason(tmp_path: Path) -> None:
    """L4 said to be 5 mm wide, seen from 0.3 m on: its 5-column bar (5 deg) cannot be it; every
    frame shows the rejected blob as a labelled line at its column, and no detection of L4."""
    from logfactory import session_doc

    doc = session_doc()
    doc["landmarks"][3]["width"] = 0.005
    doc["range_m"] = [0.3, 3.0]
    log = write_log(tmp_path / "narrow.mcap", doc=doc, between=2)
    rrd = tmp_path / "narrow.rrd"
    result = CliRunner().invoke(cli, ["replay", str(log), "--save", str(rrd), "--n-l", "100"])
    assert result.exit_code == 0, result.output
    data = _read(rrd)
    rows = [r for r in data["/camera/panorama/rejected"] if "LineStrips2D:strips" in r]
    assert len(rows) == 4 * len(MOVES)
    for r in rows:
        (label,) = r["LineStrips2D:labels"]
        assert label == "rejected: 5.0 deg wide: wider than 0.005 m at 0.3 m (1.0 deg)"
        ((u0, v0), (u1, v1)) = r["LineStrips2D:strips"][0]
        assert u0 == u1 and (v0, v1) == (0.0, HEIGHT)
    detected = [r for r in data["/camera/panorama/detections"] if "LineStrips2D:labels" in r]
    assert detected and not any(
        label.startswith("L4 ") for r in detected for label in r["LineStrips2D:labels"]
    )


def _log_times(log: Path, topic: str) -> list[int]:
    with LogReader(log) as reader:
        return [m.log_time_ns for m in reader.messages([topic])]


def test_every_row_is_at_its_log_time(
    small_log: Path, replayed: tuple[Path, dict[str, Any]]
) -> None:
    """Frames at their message's log time; a movement's rows at its end keyframe's."""
    rows = _read(replayed[0])
    frames = [r for r in rows["/camera/panorama"] if r.get("EncodedImage:blob")]
    assert sorted(r["log_time"] for r in frames) == _log_times(small_log, "/camera/panorama")
    keyframes: dict[int, list[int]] = {}
    for r in frames:
        if r.get("movement") is not None:
            keyframes.setdefault(r["movement"], []).append(r["log_time"])
    assert sorted(keyframes) == list(range(len(MOVES)))
    for entity in ("/map/estimates", "/map/trajectory", "/error/mean", "/residuals/rms_deg"):
        timed = [r for r in rows[entity] if r.get("movement") is not None]
        assert timed, entity
        for r in timed:
            assert r["log_time"] == max(keyframes[r["movement"]]), entity


def test_map_trajectory_and_errors_at_every_movement(
    replayed: tuple[Path, dict[str, Any]],
) -> None:
    """Each movement's map, path so far and errors are the summary's for that movement."""
    rrd, doc = replayed
    rows = _read(rrd)

    def at(entity: str, column: str) -> dict[int, Any]:
        return {r["movement"]: r[column] for r in rows[entity] if r.get(column) is not None}

    strips = at("/map/trajectory", "LineStrips2D:strips")
    ends = at("/map/trajectory", "Points2D:positions")
    labels = at("/map/trajectory", "Points2D:labels")
    estimates = at("/map/estimates", "Points2D:positions")
    names = at("/map/estimates", "Points2D:labels")
    errors = {n: at(f"/error/{n}", "Scalars:scalars") for n in doc["landmarks"]}
    path: list[list[float]] = []
    for entry in doc["movements"]:
        m = entry["index"]
        o = entry["observation_points"]
        path.append([*o["o1"], *o["o2"]])
        got = np.asarray(strips[m], np.float64).reshape(-1, 4)
        np.testing.assert_allclose(got, path, atol=1e-5)  # float32 in Rerun
        np.testing.assert_allclose(np.asarray(ends[m]).reshape(-1, 4), path, atol=1e-5)
        assert labels[m] == [f"O{k}.{j}" for k in range(len(path)) for j in (1, 2)]
        means = dict(zip(names[m], estimates[m], strict=True))
        assert set(means) == set(entry["landmarks"])
        for name, e in entry["landmarks"].items():
            assert means[name] == pytest.approx(e["mean"], abs=1e-5)
            assert errors[name][m][0] == pytest.approx(entry["error_m"][name], abs=1e-6)


def test_raw_frames_are_the_logged_pixels_at_their_log_times(tmp_path: Path) -> None:
    """A bgr8 log: every frame's pixels and format, at its message's log time."""
    scenario = json.loads((ROOT / "recorder/sim/scenarios/paper.json").read_text())
    scenario["trajectory"]["moves"] = 2
    spec = tmp_path / "two.json"
    spec.write_text(json.dumps(scenario))
    log, rrd = tmp_path / "raw.mcap", tmp_path / "raw.rrd"
    args = ["simulate", "--scenario", str(spec), "--out", str(log), "--encoding", "bgr8"]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    result = CliRunner().invoke(cli, ["replay", str(log), "--save", str(rrd), "--n-l", "50"])
    assert result.exit_code == 0, result.output
    with LogReader(log) as reader:
        logged = {m.log_time_ns: json.loads(m.data) for m in reader.messages(["/camera/panorama"])}
    frames = [r for r in _read(rrd)["/camera/panorama"] if r.get("Image:buffer")]
    assert sorted(r["log_time"] for r in frames) == sorted(logged)
    for r in frames:
        msg = logged[r["log_time"]]
        width, height = msg["width"], msg["height"]
        step = msg.get("step", 3 * width)
        rows = np.frombuffer(base64.b64decode(msg["data"]), np.uint8).reshape(height, step)
        pixels = rows[:, : 3 * width].ravel()
        np.testing.assert_array_equal(np.asarray(r["Image:buffer"][0], np.uint8), pixels)
        [fmt] = r["Image:format"]
        assert (fmt["width"], fmt["height"]) == (width, height)


def test_class_labels_number_the_landmarks_in_order() -> None:
    """Hand-made masks: each landmark's pixels get its number; an overlap goes to the later
    name, a landmark without a mask leaves no pixel."""
    a = np.zeros((3, 4), bool)
    a[0, :2] = True
    b = np.zeros((3, 4), bool)
    b[0, 1:3] = b[2, 3] = True
    labels = class_labels({"A": a, "B": b, "D": a}, ["A", "B", "C", "D"])
    expected = np.zeros((3, 4), np.uint8)
    expected[0, 1:3] = expected[2, 3] = 2  # B over A at (0, 1)
    expected[0, :2] = 4  # D (A's mask again) over both
    np.testing.assert_array_equal(labels, expected)
    assert labels.dtype == np.uint8


def test_detection_lines_look_along_their_bearings() -> None:
    bearings = [-3.0, -0.4, 0.0, 1.2, 3.1]
    unwrapped = UnwrappedCalibration(width=360, height=40, offset_rad=0.3, direction=-1)
    strips = detection_strips(unwrapped, bearings)
    np.testing.assert_array_equal(strips.lengths, [2] * 5)
    ends = strips.points.reshape(5, 2, 2)
    np.testing.assert_array_equal(ends[:, :, 1], [[0.0, 40.0]] * 5)  # top to bottom
    np.testing.assert_array_equal(ends[:, 0, 0], ends[:, 1, 0])  # one column
    # column u looks along offset + direction * 2 pi u / width
    got = 0.3 - 2 * np.pi * ends[:, 0, 0] / 360
    np.testing.assert_allclose(np.angle(np.exp(1j * (got - bearings))), 0.0, atol=1e-12)

    omni = OmniCalibration(width=200, height=160, cx=90.0, cy=70.0, r_min=10.0, r_max=60.0)
    ends = detection_strips(omni, bearings).points.reshape(5, 2, 2)
    np.testing.assert_allclose(ends[:, 0], [[90.0, 70.0]] * 5)  # from the mirror's centre
    dx, dy = ends[:, 1, 0] - 90.0, ends[:, 1, 1] - 70.0
    np.testing.assert_allclose(np.hypot(dx, dy), 60.0)  # out to r_max
    got = -np.pi / 2 + np.arctan2(-dy, dx)  # counter-clockwise on screen from offset -pi/2
    np.testing.assert_allclose(np.angle(np.exp(1j * (got - bearings))), 0.0, atol=1e-12)

    pinhole = PinholeCalibration(width=320, height=240, fx=300.0, fy=300.0, cx=160.0, cy=120.0)
    strips = detection_strips(pinhole, [0.2, 3.0, -0.3])  # 3.0 rad is behind the camera
    np.testing.assert_array_equal(strips.lengths, [9, 0, 9])
    lines = np.split(strips.points, [9, 9])
    for b, line in zip([0.2, -0.3], (lines[0], lines[2]), strict=True):
        # no distortion: one column, x = cx - fx tan(b) (+ 0.5: pixel centres)
        np.testing.assert_allclose(line[:, 0], 160.0 - 300.0 * np.tan(b) + 0.5, atol=1e-9)
