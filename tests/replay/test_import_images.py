"""`bslam import images`: a folder of images written here with OpenCV, a timestamps file and an
odometry CSV; the log's frames decoded by OpenCV are the images' pixels."""

from __future__ import annotations

import base64
import hashlib
import json
from pathlib import Path

import cv2
import numpy as np
from click.testing import CliRunner
from importing import on, read_back

from replay.cli import cli

W, H = 10, 4
CALIBRATION = {"model": "unwrapped", "width": W, "height": H}
LANDMARKS = {
    "landmarks": [{"name": "A", "color": "red"}, {"name": "B", "bands": ["green", "blue"]}],
    "reference": ["A", "B"],
    "vision_error_deg": 3.0,
}


def _folder(tmp_path: Path, timestamps: str) -> list[str]:
    rng = np.random.default_rng(0)
    folder = tmp_path / "frames"
    folder.mkdir()
    colour = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    grey = rng.integers(0, 256, (H, W), dtype=np.uint8)
    cv2.imwrite(str(folder / "a.png"), colour)
    cv2.imwrite(str(folder / "b.png"), grey)
    (tmp_path / "t.csv").write_text(timestamps)
    (tmp_path / "o.csv").write_text("t_s,v_mps,omega_radps\n0.5,2,0\n1.5,0,0\n")
    (tmp_path / "cal.json").write_text(json.dumps(CALIBRATION))
    (tmp_path / "lm.json").write_text(json.dumps(LANDMARKS))
    return [
        "import", "images", str(folder), "--timestamps", str(tmp_path / "t.csv"),
        "--calibration", str(tmp_path / "cal.json"), "--landmarks", str(tmp_path / "lm.json"),
        "--odometry", str(tmp_path / "o.csv"), "-o", str(tmp_path / "out.mcap"),
    ]  # fmt: skip


def test_frames_odometry_and_provenance(tmp_path: Path) -> None:
    args = _folder(tmp_path, "file,t_s\na.png,1.0\nb.png,1.25\n")
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    session, messages = read_back(tmp_path / "out.mcap")
    assert session["camera"]["calibration"]["width"] == W
    assert session["landmarks"][1] == {"name": "B", "bands": ["green", "blue"]}
    frames = on(messages, "/camera/panorama")
    assert [f["timestamp"] for f in frames] == [
        {"sec": 1, "nsec": 0}, {"sec": 1, "nsec": 250_000_000}
    ]  # fmt: skip
    colour = cv2.imread(str(tmp_path / "frames" / "a.png"))
    grey = cv2.imread(str(tmp_path / "frames" / "b.png"), cv2.IMREAD_GRAYSCALE)
    got = [cv2.imdecode(np.frombuffer(base64.b64decode(f["data"]), np.uint8), -1) for f in frames]
    assert np.array_equal(got[0], colour)
    assert np.array_equal(got[1], np.dstack([grey, grey, grey]))
    # 2 m/s for 1 s from t = 0.5 s: the pose at 1.5 s is 2 m ahead
    poses = [(p["x_m"], p["y_m"], p["theta_rad"]) for p in on(messages, "/robot/odometry_pose")]
    assert poses == [(0.0, 0.0, 0.0), (2.0, 0.0, 0.0)]
    assert [t for t, *_ in messages] == [
        "/robot/odometry_pose", "/camera/panorama", "/camera/panorama", "/robot/odometry_pose"
    ]  # fmt: skip
    info = CliRunner().invoke(cli, ["info", str(tmp_path / "out.mcap")]).output
    # six files: five are named, the last counted
    assert "imported by the images importer from t.csv (sha256 " in info
    assert "b.png" not in info and " and 1 more, " in info
    files = {f["name"]: f["sha256"] for f in session["provenance"]["files"]}
    for name in ("a.png", "b.png"):
        data = (tmp_path / "frames" / name).read_bytes()
        assert files[name] == hashlib.sha256(data).hexdigest()


def test_bad_timestamps_and_images(tmp_path: Path) -> None:
    args = _folder(tmp_path, "file,t_s\na.png,1.0\nc.png,2.0\n")
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 1
    assert result.output.startswith("Error: ") and "t.csv:3: image" in result.output
    assert "c.png does not exist" in result.output
    (tmp_path / "t.csv").write_text("file,t_s\nb.png,1.0\na.png,1.0\n")
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 1 and "t.csv:3: times must increase strictly" in result.output
    (tmp_path / "cal.json").write_text(json.dumps(CALIBRATION | {"width": 12}))
    (tmp_path / "t.csv").write_text("file,t_s\na.png,1.0\n")
    result = CliRunner().invoke(cli, args)
    assert (
        result.exit_code == 1 and "a.png is 10 x 4, but the calibration is 12 x 4" in result.output
    )
    assert not (tmp_path / "out.mcap").exists()


def test_the_catalog_range_sizes_and_band_boxes_reach_the_log(tmp_path: Path) -> None:
    """What ``calibrate colors`` and the size gate read (``range_m``, widths, a box per band)
    is carried from the landmark file into the imported session."""
    args = _folder(tmp_path, "file,t_s\na.png,1.0\nb.png,1.25\n")
    boxes = [
        {"lo": [50, 90, 40], "hi": [70, 255, 255]},
        {"lo": [110, 90, 40], "hi": [130, 255, 255]},
    ]
    catalog = dict(LANDMARKS, range_m=[0.2, 3.0])
    catalog["landmarks"] = [
        {"name": "A", "color": "red", "width": 0.05},
        {"name": "B", "bands": ["green", "blue"], "hsv": boxes, "height": 0.3},
    ]
    (tmp_path / "lm.json").write_text(json.dumps(catalog))
    assert CliRunner().invoke(cli, args).exit_code == 0
    session, _ = read_back(tmp_path / "out.mcap")
    assert session["range_m"] == [0.2, 3.0]
    assert session["landmarks"] == catalog["landmarks"]
