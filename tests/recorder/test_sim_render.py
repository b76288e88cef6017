"""The panorama renderer draws each landmark exactly at its (noisy) bearing, in both models."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from numpy.typing import NDArray

from data_schemas.angles import truncated_normal_std, wrap_rad
from data_schemas.calibration import Calibration, UnwrappedCalibration, default_omni
from data_schemas.colors import NOMINAL_BGR
from recorder.sim.render import (
    Lighting,
    RenderedFrame,
    render_panorama,
    truncated_normal,
)
from recorder.sim.world import Arena, Landmark, Pose, SimWorld

ARENA = Arena(1.05, 0.68)
CALIBRATIONS = [UnwrappedCalibration(255, 176), default_omni(320, 320)]

# Simple OpenCV HSV classes (H in 0..179): (hue ranges, S >= 100, V >= 50).
HSV_HUES = {
    "red": [(0, 10), (170, 179)],
    "yellow": [(20, 40)],
    "green": [(45, 75)],
    "cyan": [(80, 100)],
    "blue": [(105, 135)],
    "magenta": [(140, 165)],
}


def hsv_mask(image_bgr: NDArray[np.uint8], color: str) -> NDArray[np.bool_]:
    hsv = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2HSV)
    h, s, v = hsv[..., 0], hsv[..., 1], hsv[..., 2]
    hue = np.zeros(h.shape, bool)
    for lo, hi in HSV_HUES[color]:
        hue |= (h >= lo) & (h <= hi)
    return hue & (s >= 100) & (v >= 50)


def render_clean(
    pose: Pose, world: SimWorld, cal: Calibration, rng: np.random.Generator
) -> RenderedFrame:
    """A noise-free frame: no bearing noise, no pixel noise, constant lighting."""
    return render_panorama(
        pose, world, cal, rng, bearing_noise_rad=0.0, vision_error_rad=0.05, pixel_noise=0.0
    )


def pixel_bearings(cal: Calibration) -> NDArray[np.float64]:
    ys, xs = np.mgrid[0 : cal.height, 0 : cal.width] + 0.5
    if isinstance(cal, UnwrappedCalibration):
        return cal.bearing_of_column(xs)
    return cal.bearing_of_pixel(xs, ys)


def alpha_of(image: NDArray[np.uint8], empty: NDArray[np.uint8], color: str) -> NDArray[np.float64]:
    """Per-pixel coverage of ``color`` over the empty-world background (least squares)."""
    bg = empty.astype(float)
    direction = np.array(NOMINAL_BGR[color], float) - bg
    alpha = ((image.astype(float) - bg) * direction).sum(-1) / (direction**2).sum(-1)
    return np.clip(alpha, 0.0, None)


def circular_centroid(weights: NDArray[np.float64], bearings: NDArray[np.float64]) -> float:
    return math.atan2(
        float((weights * np.sin(bearings)).sum()), float((weights * np.cos(bearings)).sum())
    )


def render_one(
    cal: Calibration, pose: Pose, landmark: Landmark, rng: np.random.Generator
) -> tuple[float, float, NDArray[np.float64]]:
    """(centroid, drawn bearing, alpha) of a lone landmark on a clean frame."""
    frame = render_clean(pose, SimWorld(ARENA, (landmark,)), cal, rng)
    empty = render_clean(pose, SimWorld(ARENA, ()), cal, rng)
    alpha = alpha_of(frame.image_bgr, empty.image_bgr, landmark.color)
    return circular_centroid(alpha, pixel_bearings(cal)), frame.truth[0].bearing_drawn_rad, alpha


@pytest.mark.parametrize(
    ("cal", "n_poses"),
    [
        (CALIBRATIONS[0], 12),
        (CALIBRATIONS[1], 12),
        pytest.param(UnwrappedCalibration(1920, 960), 2, marks=pytest.mark.slow),
    ],
    ids=["unwrapped", "omni", "unwrapped-1920x960"],
)
def test_centroid_matches_drawn_bearing(cal: Calibration, n_poses: int) -> None:
    rng = np.random.default_rng(3)
    for _ in range(n_poses):
        lx, ly = rng.uniform(0.1, 0.95), rng.uniform(0.1, 0.6)
        dist, direction = rng.uniform(0.08, 0.9), rng.uniform(-math.pi, math.pi)
        pose = (
            lx - dist * math.cos(direction),
            ly - dist * math.sin(direction),
            rng.uniform(-3, 3),
        )
        lm = Landmark("A", lx, ly, "green", radius_m=rng.uniform(0.005, 0.02))
        centroid, drawn, alpha = render_one(cal, pose, lm, rng)
        assert alpha.max() > 0.2  # drawn (sub-pixel landmarks never reach full coverage)
        assert abs(math.degrees(wrap_rad(centroid - drawn))) < 0.05


@pytest.mark.parametrize("cal", CALIBRATIONS, ids=["unwrapped", "omni"])
@pytest.mark.parametrize("offset_deg", [-179.5, 180.0, 179.2])
def test_seam_straddling_landmark(cal: Calibration, offset_deg: float) -> None:
    # the landmark is right behind the robot: its bar/wedge crosses bearing +-pi
    lm = Landmark("A", 0.5, 0.3, "blue", radius_m=0.02)
    d, h = 0.25, math.radians(offset_deg)
    pose = (0.5 + d * math.cos(h), 0.3 + d * math.sin(h), h)  # heading away from the landmark
    centroid, drawn, alpha = render_one(cal, pose, lm, np.random.default_rng(0))
    assert abs(math.degrees(wrap_rad(centroid - drawn))) < 0.05
    bearings = pixel_bearings(cal)
    drawn_at = alpha > 0.5
    assert (bearings[drawn_at] > 3.0).any() and (bearings[drawn_at] < -3.0).any()
    if isinstance(cal, UnwrappedCalibration):
        assert alpha[:, 0].max() > 0.5 and alpha[:, -1].max() > 0.5


@pytest.mark.parametrize("cal", CALIBRATIONS, ids=["unwrapped", "omni"])
def test_occlusion_hides_the_farther_landmark(cal: Calibration) -> None:
    near = Landmark("N", 0.45, 0.3, "red", radius_m=0.02)
    far = Landmark("F", 0.75, 0.3, "yellow", radius_m=0.01)
    pose = (0.2, 0.3, 0.4)
    rng = np.random.default_rng(1)
    frame = render_clean(pose, SimWorld(ARENA, (near, far)), cal, rng)
    assert frame.landmark("F").occluded_fraction == 1.0
    assert not frame.landmark("F").visible
    assert frame.landmark("N").visible
    assert hsv_mask(frame.image_bgr, "yellow").sum() == 0
    assert hsv_mask(frame.image_bgr, "red").sum() > 20
    # shift the robot sideways: now both are seen
    frame = render_clean((0.2, 0.45, 0.4), SimWorld(ARENA, (near, far)), cal, rng)
    assert frame.landmark("F").visible
    assert hsv_mask(frame.image_bgr, "yellow").sum() > 5


def test_nearer_landmarks_are_taller() -> None:
    cal = UnwrappedCalibration(255, 176)
    rows = []
    for dist in (0.1, 0.3, 0.9):
        lm = Landmark("A", 0.1 + dist, 0.3, "magenta")
        image = render_clean(
            (0.1, 0.3, 0.0), SimWorld(ARENA, (lm,)), cal, np.random.default_rng(0)
        ).image_bgr
        rows.append(int(hsv_mask(image, "magenta").any(axis=1).sum()))
    assert rows[0] > rows[1] > rows[2] > 5


def test_truncated_noise_is_bounded_and_has_the_right_std() -> None:
    rng = np.random.default_rng(42)
    std, eps = math.radians(1.0), math.radians(3.0)
    x = truncated_normal(rng, std, eps, 200_000)
    assert np.abs(x).max() <= eps
    assert np.abs(x).max() > 0.95 * eps  # the tails are really there
    assert float(x.std()) == pytest.approx(truncated_normal_std(std, eps), rel=0.01)
    assert truncated_normal_std(std, eps) == pytest.approx(std, rel=0.02)  # 3 sigma: ~ std
    # heavy truncation: bound below the std
    y = truncated_normal(rng, 2.0, 1.0, 100_000)
    assert np.abs(y).max() <= 1.0
    assert float(y.std()) == pytest.approx(truncated_normal_std(2.0, 1.0), rel=0.01)
    assert truncated_normal_std(2.0, 1.0) < 0.6
    assert not truncated_normal(rng, 0.0, 1.0, 10).any()


def test_rendered_bearing_noise_never_exceeds_eps() -> None:
    cal = UnwrappedCalibration(64, 16)
    world = SimWorld(ARENA, (Landmark("A", 0.3, 0.3, "red"), Landmark("B", 0.8, 0.5, "cyan")))
    rng = np.random.default_rng(9)
    std, eps = math.radians(2.0), math.radians(3.0)
    errors = []
    for _ in range(1500):
        frame = render_panorama(
            (0.55, 0.2, 1.0), world, cal, rng, bearing_noise_rad=std, vision_error_rad=eps
        )
        errors += [wrap_rad(t.bearing_drawn_rad - t.bearing_true_rad) for t in frame.truth]
    err = np.array(errors)
    assert np.abs(err).max() <= eps + 1e-12
    assert float(err.std()) == pytest.approx(truncated_normal_std(std, eps), rel=0.05)


@pytest.mark.parametrize("cal", CALIBRATIONS, ids=["unwrapped", "omni"])
def test_background_never_looks_like_a_landmark(cal: Calibration) -> None:
    rng = np.random.default_rng(5)
    empty = SimWorld(ARENA, ())
    strong = Lighting(gain_jitter=0.2, gradient=0.15)
    for _ in range(12):
        pose = (rng.uniform(0, 1.05), rng.uniform(0, 0.68), rng.uniform(-3, 3))
        image = render_panorama(
            pose,
            empty,
            cal,
            rng,
            bearing_noise_rad=0.0,
            vision_error_rad=0.05,
            pixel_noise=4.0,
            lighting=strong,
        ).image_bgr
        for color in HSV_HUES:
            assert hsv_mask(image, color).sum() == 0, color


@pytest.mark.parametrize("cal", CALIBRATIONS, ids=["unwrapped", "omni"])
def test_every_landmark_colour_is_seen_in_its_class(cal: Calibration) -> None:
    # guards the thresholds above: nominal colours under lighting and noise fall in their class
    colors = list(NOMINAL_BGR)
    lms = tuple(
        Landmark(c, 0.52 + 0.25 * math.cos(k * 1.0), 0.34 + 0.25 * math.sin(k * 1.0), c, 0.015)
        for k, c in enumerate(colors)
    )
    rng = np.random.default_rng(2)
    frame = render_panorama(
        (0.52, 0.34, 0.3),
        SimWorld(ARENA, lms),
        cal,
        rng,
        bearing_noise_rad=0.0,
        vision_error_rad=0.05,
        lighting=Lighting(),
    )
    bearings = pixel_bearings(cal)
    for t in frame.truth:
        mask = hsv_mask(frame.image_bgr, t.color)
        assert mask.sum() > 20, t.color
        assert abs(
            wrap_rad(circular_centroid(mask.astype(float), bearings) - t.bearing_drawn_rad)
        ) < math.radians(1.0)


def test_frames_are_reproducible_and_well_formed() -> None:
    cal = UnwrappedCalibration(255, 176)
    world = SimWorld(ARENA, (Landmark("A", 0.3, 0.3, "red"),))

    def frame(seed: int) -> NDArray[np.uint8]:
        return render_panorama(
            (0.5, 0.4, 0.2),
            world,
            cal,
            np.random.default_rng(seed),
            bearing_noise_rad=0.02,
            vision_error_rad=0.05,
            lighting=Lighting(),
        ).image_bgr

    a = frame(1)
    assert a.shape == (176, 255, 3) and a.dtype == np.uint8
    assert np.array_equal(a, frame(1))
    assert not np.array_equal(a, frame(2))


@pytest.mark.parametrize("cal", CALIBRATIONS, ids=lambda c: c.model)
@pytest.mark.parametrize("bands", [("magenta", "yellow"), ("cyan", "red", "green")])
def test_bands_are_painted_top_to_bottom_with_equal_heights(
    cal: Calibration, bands: tuple[str, ...]
) -> None:
    """Unwrapped: the top band in the upper rows; omni: the top band outermost on the ray."""
    world = SimWorld(ARENA, (Landmark("C", 0.7, 0.34, None, radius_m=0.02, bands=bands),))
    frame = render_clean((0.4, 0.34, 0.0), world, cal, np.random.default_rng(0))
    assert frame.truth[0].color == "-".join(bands)
    if isinstance(cal, UnwrappedCalibration):
        ys, _ = np.mgrid[0 : cal.height, 0 : cal.width]
        height = ys.astype(float)  # grows downwards: from the top band to the bottom one
    else:
        ys, xs = np.mgrid[0 : cal.height, 0 : cal.width] + 0.5
        height = -np.hypot(xs - cal.cx, ys - cal.cy)  # grows inwards
    centres, sizes = [], []
    for color in bands:
        mask = hsv_mask(frame.image_bgr, color)
        assert mask.sum() > 10, color
        centres.append(float(np.median(height[mask])))
        sizes.append(float(np.ptp(height[mask])))
    assert centres == sorted(centres)
    # equal heights on the cylinder: image extents agree within perspective (same elevation span)
    assert max(sizes) < 2.0 * min(sizes)
