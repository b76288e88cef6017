"""Pinhole cameras: the camera model against OpenCV's forward projection and hand-computed
values, calibration files (ROS camera_info, OpenCV FileStorage), bearings on simulated frames
(with distortion), and the field of view.

Oracles: ``cv2.projectPoints`` / ``cv2.fisheye.projectPoints`` (the forward model; the code
under test uses the inverse, ``undistortPoints``), hand-computed projections, and the
simulator's renderer, which inverts the lens with its own Newton iteration
(``recorder/sim/lens.py``). Figures are printed with ``-s``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from data_schemas.calibration import (
    PinholeCalibration,
    calibration_from_dict,
    pinhole_from_camera_info,
)
from data_schemas.codec import validate
from data_schemas.errors import CalibrationError
from data_schemas.session import LandmarkSpec
from pipeline.association.predict import outside_view
from pipeline.bearings import BearingExtractor, pixel_bearings
from pipeline.bearings.pinhole import field_of_view_rad
from recorder.session import load_calibration_file
from recorder.sim.lens import project
from recorder.sim.render import Lighting, render_panorama
from recorder.sim.scenario import builtin_scenario, simulated_pinhole
from recorder.sim.world import Landmark, SimWorld

DEG = math.pi / 180.0

#: One camera per distortion model, strong enough that ignoring it would cost degrees.
CAMERAS = {
    "none": PinholeCalibration(640, 480, 520.0, 515.0, 322.0, 236.0),
    "plumb_bob": PinholeCalibration(
        640, 480, 520.0, 515.0, 322.0, 236.0, (-0.30, 0.11, 0.0012, -0.0009, -0.02)
    ),
    "rational_polynomial": PinholeCalibration(
        640,
        480,
        520.0,
        515.0,
        322.0,
        236.0,
        (0.8, -0.3, 0.001, 0.0005, 0.05, 1.1, -0.2, 0.1),
        "rational_polynomial",
    ),
    "equidistant": PinholeCalibration(
        640, 480, 300.0, 300.0, 320.0, 240.0, (0.05, -0.02, 0.004, -0.001), "equidistant"
    ),
}


def _project_cv(cal: PinholeCalibration, xyz: np.ndarray) -> np.ndarray:
    """OpenCV's projection of camera-frame points, as continuous pixel coordinates (+0.5)."""
    zero = np.zeros(3)
    d = np.asarray(cal.distortion, np.float64)
    pts = xyz.reshape(-1, 1, 3).astype(np.float64)
    if cal.distortion_model == "equidistant":
        uv, _ = cv2.fisheye.projectPoints(pts, zero, zero, cal.camera_matrix, d)
    else:
        uv, _ = cv2.projectPoints(pts, zero, zero, cal.camera_matrix, d if d.size else None)
    return np.asarray(uv, np.float64).reshape(-1, 2) + 0.5


def _points_in_view(cal: PinholeCalibration, rng: np.random.Generator, n: int) -> np.ndarray:
    """Camera-frame points (x right, y down, z forward) that OpenCV projects into the image."""
    out = []
    while len(out) < n:
        b = rng.uniform(-50 * DEG, 50 * DEG)
        e = rng.uniform(-35 * DEG, 35 * DEG)
        r = rng.uniform(0.2, 5.0)
        xyz = r * np.array([-math.sin(b) * math.cos(e), -math.sin(e), math.cos(b) * math.cos(e)])
        uv = _project_cv(cal, xyz)[0]
        if 0 <= uv[0] <= cal.width and 0 <= uv[1] <= cal.height:
            out.append(xyz)
    return np.array(out)


@pytest.mark.parametrize("model", list(CAMERAS))
@pytest.mark.parametrize("offset_deg", [0.0, 90.0, -135.0])
def test_bearing_of_pixel_inverts_opencv_projection(model: str, offset_deg: float) -> None:
    """A point projected by OpenCV reads back at its true bearing, for every distortion model
    and mounted yaw: bearing = offset + atan2(-x, z), CCW positive, 0 along the optical axis."""
    base = CAMERAS[model]
    cal = PinholeCalibration(
        base.width,
        base.height,
        base.fx,
        base.fy,
        base.cx,
        base.cy,
        base.distortion,
        base.distortion_model,
        offset_rad=offset_deg * DEG,
    )
    xyz = _points_in_view(cal, np.random.default_rng(5), 300)
    uv = _project_cv(cal, xyz)
    got = pixel_bearings(cal, uv[:, 0], uv[:, 1])
    truth = offset_deg * DEG + np.arctan2(-xyz[:, 0], xyz[:, 2])
    err = np.abs(np.remainder(got - truth + math.pi, 2 * math.pi) - math.pi)
    assert err.max() < 1e-6


def test_hand_computed_pinhole_bearings() -> None:
    """No distortion: fx = 500, cx = 319.5 (OpenCV), so continuous x = 320 is the axis and
    x = 820 is xn = 1 (45 deg to the right); mounted 90 deg to the left."""
    cal = PinholeCalibration(640, 480, 500.0, 500.0, 319.5, 239.5)
    got = pixel_bearings(cal, np.array([320.0, 820.0, -180.0]), np.array([240.0, 10.0, 400.0]))
    assert got == pytest.approx([0.0, -45 * DEG, 45 * DEG], abs=1e-12)
    left = PinholeCalibration(640, 480, 500.0, 500.0, 319.5, 239.5, offset_rad=90 * DEG)
    assert pixel_bearings(left, np.array([820.0]), np.array([240.0])) == pytest.approx(
        [45 * DEG], abs=1e-12
    )
    lo, hi = field_of_view_rad(cal)
    # the image edges x = 0 and 640 are at xn = -0.64 and +0.64
    assert (lo, hi) == pytest.approx((-math.atan(0.64), math.atan(0.64)), abs=1e-9)


@pytest.mark.parametrize("model", ["plumb_bob", "rational_polynomial", "equidistant"])
def test_simulator_lens_matches_opencv(model: str) -> None:
    """The renderer's own distortion model projects as OpenCV does (so the simulated frames
    check the extraction's undistortion independently)."""
    cal = CAMERAS[model]
    xyz = _points_in_view(cal, np.random.default_rng(8), 200)
    u, v = project(cal, xyz[:, 0] / xyz[:, 2], xyz[:, 1] / xyz[:, 2])
    assert np.column_stack([u, v]) == pytest.approx(_project_cv(cal, xyz), abs=1e-6)


def test_json_round_trip_and_schema() -> None:
    cal = CAMERAS["rational_polynomial"]
    doc = cal.to_dict()
    validate("bslam.Calibration", doc)
    assert calibration_from_dict(json.loads(json.dumps(doc))) == cal


def test_camera_info_forms() -> None:
    """ROS 2 CameraInfo (k, d), ROS 1 (K, D), camera_calibration's YAML mapping, an OpenCV
    matrix, and fisheye as ``equidistant``."""
    k = [500.0, 0.0, 319.5, 0.0, 501.0, 239.5, 0.0, 0.0, 1.0]
    want = PinholeCalibration(640, 480, 500.0, 501.0, 319.5, 239.5, (-0.1, 0.01, 0.0, 0.0, 0.002))
    ros2 = {"width": 640, "height": 480, "k": k, "d": list(want.distortion)}
    ros2["distortion_model"] = "plumb_bob"
    assert pinhole_from_camera_info(ros2) == want
    ros1 = {"width": 640, "height": 480, "K": k, "D": list(want.distortion)}
    assert pinhole_from_camera_info(ros1) == want
    yaml_like = {
        "image_width": 640,
        "image_height": 480,
        "camera_matrix": {"rows": 3, "cols": 3, "data": k},
        "distortion_coefficients": {"rows": 1, "cols": 5, "data": list(want.distortion)},
    }
    assert pinhole_from_camera_info(yaml_like) == want
    fish = {"width": 640, "height": 480, "K": np.reshape(k, (3, 3)).tolist()}
    fish |= {"D": [0.1, 0.0, 0.0, 0.0], "distortion_model": "fisheye", "offset_deg": 30.0}
    got = pinhole_from_camera_info(fish)
    assert got.distortion_model == "equidistant"
    assert got.offset_rad == pytest.approx(30 * DEG)


@pytest.mark.parametrize(
    ("doc", "message"),
    [
        ({"width": 640, "height": 480, "k": [1.0] * 8}, "9 values"),
        ({"width": 640, "height": 480, "k": [500, 3, 320, 0, 500, 240, 0, 0, 1]}, "no skew"),
        ({"height": 480, "k": [500, 0, 320, 0, 500, 240, 0, 0, 1]}, "'width' or 'image_width'"),
        (
            {"width": 640, "height": 480, "k": [500, 0, 320, 0, 500, 240, 0, 0, 1], "d": [0.1]},
            "takes 4 or 5 coefficients",
        ),
        (
            {
                "width": 640,
                "height": 480,
                "k": [500, 0, 320, 0, 500, 240, 0, 0, 1],
                "distortion_model": "kannala",
            },
            "unknown distortion model",
        ),
        ({"width": 640, "height": 480, "k": [-5, 0, 320, 0, 500, 240, 0, 0, 1]}, "positive"),
    ],
)
def test_bad_camera_info(doc: dict[str, object], message: str) -> None:
    with pytest.raises(CalibrationError, match=message):
        pinhole_from_camera_info(doc)


def test_calibration_files(tmp_path: Path) -> None:
    """OpenCV FileStorage YAML and JSON, and a ROS camera_calibration YAML, load as pinholes."""
    k = np.array([[500.0, 0.0, 320.0], [0.0, 502.0, 241.0], [0.0, 0.0, 1.0]])
    d = np.array([[-0.2], [0.05], [0.001], [0.0], [0.01]])
    want = PinholeCalibration(640, 480, 500.0, 502.0, 320.0, 241.0, tuple(d.ravel()))
    for suffix in (".yml", ".json", ".xml"):
        path = str(tmp_path / f"cv{suffix}")
        fs = cv2.FileStorage(path, cv2.FILE_STORAGE_WRITE)
        fs.write("image_width", 640)
        fs.write("image_height", 480)
        fs.write("camera_matrix", k)
        fs.write("distortion_coefficients", d)
        fs.release()
        assert load_calibration_file(path) == want, suffix
    ros = tmp_path / "ros.yaml"
    ros.write_text(
        "image_width: 640\nimage_height: 480\ncamera_name: front\ncamera_matrix:\n  rows: 3\n"
        "  cols: 3\n  data: [500.0, 0.0, 320.0, 0.0, 502.0, 241.0, 0.0, 0.0, 1.0]\n"
        "distortion_model: plumb_bob\ndistortion_coefficients:\n  rows: 1\n  cols: 5\n"
        "  data: [-0.2, 0.05, 0.001, 0.0, 0.01]\n"
    )
    assert load_calibration_file(ros) == want
    bad = tmp_path / "bad.yaml"
    bad.write_text("image_width: [1, 2\n")
    with pytest.raises(CalibrationError, match="FileStorage"):
        load_calibration_file(bad)


@pytest.mark.parametrize("distortion", [(), (-0.28, 0.09, 0.001, -0.0005, -0.02)])
def test_bearings_on_simulated_pinhole_frames(distortion: tuple[float, ...]) -> None:
    """Goal: pinhole bearings on simulated frames within 0.3 deg RMS (distortion on), every
    landmark fully in view found, none outside the view reported."""
    world = builtin_scenario("paper").world()
    cal = simulated_pinhole(640, 480, 60 * DEG, distortion)
    extractor = BearingExtractor(cal, [LandmarkSpec(lm.name, lm.color) for lm in world.landmarks])
    lo, hi = extractor.field_of_view_rad or (0.0, 0.0)
    # barrel distortion bends the image's edges: whole in every row between these bearings
    rows = np.arange(cal.height) + 0.5
    inner_lo = float(pixel_bearings(cal, np.full_like(rows, cal.width), rows).max())
    inner_hi = float(pixel_bearings(cal, np.zeros_like(rows), rows).min())
    assert lo - 1e-12 <= inner_lo < inner_hi <= hi + 1e-12
    rng = np.random.default_rng(21)
    errors, n_out = [], 0
    for _ in range(120):
        pose = (rng.uniform(0.05, 1.0), rng.uniform(0.05, 0.63), rng.uniform(-math.pi, math.pi))
        frame = render_panorama(
            pose, world, cal, rng, bearing_noise_rad=0.0, vision_error_rad=0.05,
            lighting=Lighting(),
        )  # fmt: skip
        found = extractor.extract(frame.image_bgr)
        for t in frame.truth:
            b, half = t.bearing_drawn_rad, t.half_width_rad
            whole = b - half > inner_lo + 0.5 * DEG and b + half < inner_hi - 0.5 * DEG
            if whole and t.occluded_fraction == 0:
                got = found[t.name].bearing_rad
                assert got is not None, t
                errors.append(math.remainder(got - b, 2 * math.pi))
            elif b + half < lo or b - half > hi:
                n_out += 1
                assert not found[t.name].visible, t
    rms = math.degrees(math.sqrt(np.mean(np.square(errors))))
    print(f"\npinhole 640x480 60 deg, D={distortion}: {len(errors)} views, RMS {rms:.3f} deg")
    assert len(errors) > 40 and n_out > 150
    assert rms <= 0.3


def test_blob_mean_is_angular_centre_for_a_wide_landmark() -> None:
    """A landmark near the image edge spans many pixels; weighting pixels by their angular width
    keeps its bearing at its centre (an unweighted pixel mean is pulled outwards)."""
    cal = simulated_pinhole(640, 480, 90 * DEG)
    world = SimWorld(
        builtin_scenario("paper").world().arena,
        (Landmark("A", 0.5, 0.30, "red", radius_m=0.04), Landmark("B", 0.9, 0.6, "blue")),
    )
    pose = (0.3, 0.1, math.atan2(0.2, 0.2) - 35 * DEG)  # A about 35 deg left of the axis
    frame = render_panorama(
        pose, world, cal, np.random.default_rng(0), bearing_noise_rad=0.0, vision_error_rad=0.05
    )
    truth = frame.landmark("A")
    assert math.degrees(truth.half_width_rad) > 5.0
    got = BearingExtractor(cal, [LandmarkSpec("A", "red"), LandmarkSpec("B", "blue")]).extract(
        frame.image_bgr
    )["A"]
    assert got.bearing_rad == pytest.approx(truth.bearing_drawn_rad, abs=0.05 * DEG)


def test_outside_view_is_beyond_the_gate() -> None:
    """A 60 deg view looking 90 deg left: predictions past an edge by more than n_std stds are
    outside; inside, or near an edge within the margin, they are not; a panorama has no edge."""
    view = (60 * DEG, 120 * DEG)
    bearings = np.array([90, 119, 125, 130, -90, 179, 55.5, 54.5]) * DEG
    std = np.full(bearings.size, 1.5 * DEG)
    got = outside_view(bearings, std, view, n_std=3.0)
    # past the edge by: -, -, 5 (< 4.5? no: 5 > 4.5), 10, far, 59, 4.5 (not >), 5.5
    assert got.tolist() == [False, False, True, True, True, True, False, True]
    assert not outside_view(bearings, std, None, n_std=3.0).any()
    wrap = (170 * DEG, 230 * DEG)  # a view across the +-180 deg seam
    assert outside_view(
        np.array([-170.0, 175.0, 100.0]) * DEG, std[:3], wrap, n_std=0.0
    ).tolist() == [
        False,
        False,
        True,
    ]
