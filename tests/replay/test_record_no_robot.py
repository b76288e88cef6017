"""`bslam record --no-robot`: a video written here with OpenCV (MJPG) of a simulated drive's
frames, and its odometry as a CSV, into a log that the driving path maps."""

from __future__ import annotations

import base64
import json
import math
import os
import signal
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from click.testing import CliRunner
from importing import on, read_back
from mcap.reader import make_reader

from recorder.record import Progress, RecordingInterrupted
from recorder.sim.scenario import simulated_pinhole
from replay.cli import cli
from replay.drive_sim import DriveCamera, simulate_drive_log
from replay.importers.camera_only import CameraOnlySpec, record_camera_only

PERIOD_S = 0.2  # the simulated camera's frame period: 5 frames per second


def _ns(doc: dict[str, Any]) -> int:
    return int(doc["timestamp"]["sec"]) * 10**9 + int(doc["timestamp"]["nsec"])


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """A simulated pinhole drive's log, and the video, odometry CSV, calibration and landmark
    files made from it here (times in seconds from the first frame)."""
    folder = tmp_path_factory.mktemp("norobot")
    camera = DriveCamera(simulated_pinhole(320, 240, math.radians(60.0)), frame_period_s=PERIOD_S)
    simulate_drive_log(folder / "sim.mcap", arena="square", duration_s=60.0, seed=5, camera=camera)
    session, messages = read_back(folder / "sim.mcap")
    frames = on(messages, "/camera/panorama")
    t0_ns = _ns(frames[0])
    video = cv2.VideoWriter(
        str(folder / "drive.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 1 / PERIOD_S, (320, 240)
    )
    for f in frames:
        video.write(cv2.imdecode(np.frombuffer(base64.b64decode(f["data"]), np.uint8), -1))
    video.release()
    odometry = on(messages, "/robot/odometry_pose")
    lines = ["t_s,x_m,y_m,theta_rad"]
    lines += [
        f"{(_ns(o) - t0_ns) / 1e9!r},{o['x_m']!r},{o['y_m']!r},{o['theta_rad']!r}"
        for o in odometry
        if _ns(o) >= t0_ns
    ]
    (folder / "odo.csv").write_text("\n".join(lines) + "\n")
    (folder / "cal.json").write_text(json.dumps(session["camera"]["calibration"]))
    catalog = {
        k: session[k] for k in ("landmarks", "reference", "vision_error_deg") if k in session
    }
    (folder / "lm.json").write_text(json.dumps(catalog))
    return {"folder": folder, "session": session, "frames": frames, "lines": lines[1:]}


def _record(folder: Path, *extra: str) -> list[str]:
    return [
        "record", "--no-robot", "--camera", str(folder / "drive.avi"),
        "--calibration", str(folder / "cal.json"), "--landmarks", str(folder / "lm.json"),
        *extra,
    ]  # fmt: skip


def test_every_frame_at_the_video_times_and_the_odometry_poses(drive: dict[str, Any]) -> None:
    folder = drive["folder"]
    out = folder / "rec.mcap"
    args = _record(folder, "--odometry", str(folder / "odo.csv"), "--out", str(out))
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    assert f"{len(drive['frames'])} frames" in result.output
    session, messages = read_back(out)
    frames = on(messages, "/camera/panorama")
    # every frame, at the video's own times: frame k at k x 0.2 s (written at 5 frames per second)
    assert [_ns(f) for f in frames] == [k * 200_000_000 for k in range(len(drive["frames"]))]
    # the pixels: the video's frames as OpenCV decodes them again
    capture = cv2.VideoCapture(str(folder / "drive.avi"))
    for f in frames[:: len(frames) // 5]:
        index = frames.index(f)
        capture.set(cv2.CAP_PROP_POS_FRAMES, index)
        ok, expected = capture.read()
        got = cv2.imdecode(np.frombuffer(base64.b64decode(f["data"]), np.uint8), -1)
        assert ok and np.array_equal(got, expected)
    # the odometry poses: the CSV's rows, exactly
    odometry = on(messages, "/robot/odometry_pose")
    rows = [tuple(float(v) for v in line.split(",")) for line in drive["lines"]]
    assert len(odometry) == len(rows)
    for o, (t_s, x, y, theta) in zip(odometry, rows, strict=True):
        assert _ns(o) == round(t_s * 1e9)
        assert (o["x_m"], o["y_m"], o["theta_rad"]) == (x, y, theta)
    assert not on(messages, "/robot/movement")
    assert session["provenance"]["kind"] == "camera"
    assert session["camera"]["calibration"] == drive["session"]["camera"]["calibration"]


def test_process_maps_the_recording_through_the_driving_path(drive: dict[str, Any]) -> None:
    folder = drive["folder"]
    out = folder / "mapped.mcap"
    args = _record(folder, "--odometry", str(folder / "odo.csv"), "--out", str(out))
    assert CliRunner().invoke(cli, args).exit_code == 0
    summary = folder / "s.json"
    result = CliRunner().invoke(cli, ["process", str(out), "--summary", str(summary)])
    assert result.exit_code == 0, result.output
    doc = json.loads(summary.read_text())
    assert doc["method"]["estimator"] == "driving"
    truth = {t["name"]: complex(t["x_m"], t["y_m"]) for t in drive["session"]["truth"]["landmarks"]}
    assert set(doc["landmarks"]) == set(truth) - {"L1", "L2"}  # every landmark besides the pair
    # the map (L1 at 0, L2 at 1) against the simulation's truth after the best similarity,
    # fitted here with complex numbers: truth = a * map + b by least squares
    est = {"L1": 0j, "L2": 1 + 0j, **{n: complex(*e["mean"]) for n, e in doc["landmarks"].items()}}
    names = sorted(est)
    z = np.array([est[n] for n in names])
    w = np.array([truth[n] for n in names])
    (a, b), *_ = np.linalg.lstsq(np.column_stack([z, np.ones_like(z)]), w, rcond=None)
    errors_m = np.abs(a * z + b - w)
    assert errors_m.mean() < 0.12 and errors_m.max() < 0.25, errors_m


def test_no_port_nor_no_robot_and_odometry_with_a_robot_are_usage_errors(
    drive: dict[str, Any],
) -> None:
    folder = drive["folder"]
    args = _record(folder, "--out", str(folder / "x.mcap"))
    result = CliRunner().invoke(cli, [a for a in args if a != "--no-robot"])
    assert result.exit_code == 2 and "give --port (a robot) or --no-robot" in result.output
    result = CliRunner().invoke(cli, [*args, "--port", "/dev/ttyUSB0"])
    assert result.exit_code == 2 and "give --port (a robot) or --no-robot" in result.output
    bad = folder / "bad.csv"
    bad.write_text("t_s,x_m,y_m,theta_rad\n1.0,0,0,0\n0.5,0,0,0\n")
    result = CliRunner().invoke(cli, [*args, "--odometry", str(bad)])
    assert result.exit_code == 1
    assert result.output.startswith("Error: ") and "times must increase strictly" in result.output
    assert not (folder / "x.mcap").exists()


def test_an_image_sequence_is_recorded_at_the_rate_given(drive: dict[str, Any]) -> None:
    """Images carry no times: frame i at i / --rate seconds; the pixels are the files'."""
    folder = drive["folder"]
    for i, f in enumerate(drive["frames"][:3]):
        (folder / f"seq_{i:03d}.png").write_bytes(base64.b64decode(f["data"]))
    out = folder / "seq.mcap"
    args = _record(folder, "--rate", "4", "--out", str(out))
    args[args.index("--camera") + 1] = str(folder / "seq_%03d.png")
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    _, messages = read_back(out)
    frames = on(messages, "/camera/panorama")
    assert [_ns(f) for f in frames] == [0, 250_000_000, 500_000_000]
    for i, f in enumerate(frames):
        expected = cv2.imread(str(folder / f"seq_{i:03d}.png"))
        got = cv2.imdecode(np.frombuffer(base64.b64decode(f["data"]), np.uint8), -1)
        assert np.array_equal(got, expected)
    assert not on(messages, "/robot/odometry_pose")


def test_a_stop_signal_finishes_and_indexes_the_log(drive: dict[str, Any]) -> None:
    """SIGINT after the 10th frame: the next frame is not read, the log is indexed with 10."""
    folder = drive["folder"]
    spec = CameraOnlySpec(
        str(folder / "drive.avi"), folder / "cal.json", folder / "lm.json", None, rate_hz=5.0
    )

    def stop_at_ten(p: Progress) -> None:
        if p.frames == 10:
            os.kill(os.getpid(), signal.SIGINT)

    out = folder / "stopped.mcap"
    with pytest.raises(RecordingInterrupted):
        record_camera_only(out, spec, progress=stop_at_ten)
    with out.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        counts = {
            summary.channels[c].topic: n
            for c, n in summary.statistics.channel_message_counts.items()
        }
    assert counts["/camera/panorama"] == 10 < len(drive["frames"])


@pytest.mark.slow  # three recordings/imports and three maps
def test_the_video_the_folder_of_its_frames_and_import_images_map_alike(
    drive: dict[str, Any],
) -> None:
    """The video's frames decoded by OpenCV into a folder (name order not numeric order on
    purpose, and a file that is not an image): ``record --no-robot`` of the folder at 5 frames
    per second stores the same frames at the same times, and ``bslam import images`` of the folder
    with its timestamps maps as the video's recording does."""
    folder = drive["folder"]
    images = folder / "decoded"
    images.mkdir()
    (images / "notes.txt").write_text("not an image\n")
    capture = cv2.VideoCapture(str(folder / "drive.avi"))
    names = []
    while True:
        ok, image = capture.read()
        if not ok:
            break
        names.append(f"f{len(names):04d}.png")
        cv2.imwrite(str(images / names[-1]), image)
    (folder / "times.csv").write_text(
        "file,t_s\n" + "".join(f"{n},{k * PERIOD_S:.1f}\n" for k, n in enumerate(names))
    )
    common = ["--calibration", str(folder / "cal.json"), "--landmarks", str(folder / "lm.json")]
    odometry = ["--odometry", str(folder / "odo.csv")]
    runs = {
        "video": ["record", "--no-robot", "--camera", str(folder / "drive.avi")],
        "folder": ["record", "--no-robot", "--camera", str(images), "--rate", "5"],
        "import": ["import", "images", str(images), "--timestamps", str(folder / "times.csv")],
    }
    maps = {}
    logs = {}
    for name, args in runs.items():
        out = folder / f"alike_{name}.mcap"
        result = CliRunner().invoke(cli, [*args, *common, *odometry, "--out", str(out)])
        assert result.exit_code == 0, result.output
        logs[name] = read_back(out)[1]
        summary = folder / f"alike_{name}.json"
        assert (
            CliRunner().invoke(cli, ["process", str(out), "--summary", str(summary)]).exit_code == 0
        )
        maps[name] = json.loads(summary.read_text())["landmarks"]
    frames = {n: on(m, "/camera/panorama") for n, m in logs.items()}
    assert len(frames["video"]) == len(names)
    for a, b in zip(frames["video"], frames["folder"], strict=True):
        assert a["timestamp"] == b["timestamp"] and a["data"] == b["data"]
    for a, b in zip(frames["video"], frames["import"], strict=True):
        assert a["timestamp"] == b["timestamp"]
        assert np.array_equal(
            cv2.imdecode(np.frombuffer(base64.b64decode(a["data"]), np.uint8), -1),
            cv2.imdecode(np.frombuffer(base64.b64decode(b["data"]), np.uint8), -1),
        )
    assert maps["video"] == maps["folder"] == maps["import"]
    truth = {t["name"] for t in drive["session"]["truth"]["landmarks"]}
    assert set(maps["video"]) == truth - {"L1", "L2"}


def test_a_folder_without_images_or_with_a_bad_one_is_one_line(drive: dict[str, Any]) -> None:
    folder = drive["folder"]
    empty = folder / "empty"
    empty.mkdir()
    args = _record(folder, "--out", str(folder / "e.mcap"))
    args[args.index("--camera") + 1] = str(empty)
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 1 and result.output.startswith("Error: camera folder ")
    assert "holds no image" in result.output and not (folder / "e.mcap").exists()
    (empty / "a.png").write_bytes(base64.b64decode(drive["frames"][0]["data"]))
    (empty / "b.png").write_text("not a PNG")
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 1 and "b.png cannot be read" in result.output
    _, messages = read_back(folder / "e.mcap")  # the frame before it is kept, indexed
    assert len(on(messages, "/camera/panorama")) == 1
