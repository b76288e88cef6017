"""Bearing extraction on frames from the real simulator renderer (both camera models).

Truth is what the renderer drew (``bearing_drawn_rad``); RMS figures are printed (``-s``).
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from data_schemas.calibration import Calibration, UnwrappedCalibration, default_omni
from data_schemas.errors import ImageError
from data_schemas.session import LandmarkSpec
from pipeline.bearings import BearingExtractor, Detection, decode_frame
from recorder.sim.render import Lighting, RenderedFrame, render_panorama
from recorder.sim.scenario import builtin_scenario
from recorder.sim.world import Landmark, Pose, SimWorld

WIDTH, HEIGHT = 255, 176
CALIBRATIONS: dict[str, Calibration] = {
    "unwrapped": UnwrappedCalibration(WIDTH, HEIGHT),
    "omni": default_omni(WIDTH, HEIGHT),
}
MODELS = list(CALIBRATIONS)
EPS_RAD = math.radians(3.0)
BAD_LIGHT = Lighting(gain_jitter=0.3, gradient=0.25)


def _paper_world() -> SimWorld:
    return builtin_scenario("paper").world()


def _catalog(world: SimWorld) -> list[LandmarkSpec]:
    return [LandmarkSpec(lm.name, lm.color) for lm in world.landmarks]


def _err_deg(a_rad: float, b_rad: float) -> float:
    return math.degrees(math.remainder(a_rad - b_rad, 2 * math.pi))


def _random_pose(world: SimWorld, rng: np.random.Generator) -> Pose:
    """A pose inside the arena, at least 6 cm from every landmark centre."""
    while True:
        x = rng.uniform(0.05, world.arena.width_m - 0.05)
        y = rng.uniform(0.05, world.arena.height_m - 0.05)
        if np.hypot(*(world.xy_world - (x, y)).T).min() > 0.06:
            return (x, y, rng.uniform(-math.pi, math.pi))


def _render(
    world: SimWorld,
    cal: Calibration,
    pose: Pose,
    rng: np.random.Generator,
    *,
    pixel_noise: float = 2.0,
    lighting: Lighting | None = None,
) -> RenderedFrame:
    return render_panorama(
        pose,
        world,
        cal,
        rng,
        bearing_noise_rad=0.0,
        vision_error_rad=EPS_RAD,
        pixel_noise=pixel_noise,
        lighting=lighting,
    )


def _clean_view_errors(
    model: str, method: str, *, pixel_noise: float, lighting: Lighting | None, n_frames: int
) -> list[float]:
    """Bearing errors (deg) of unoccluded landmarks over random poses; checks absent ones."""
    world, cal = _paper_world(), CALIBRATIONS[model]
    extractor = BearingExtractor(cal, _catalog(world), method=method)  # type: ignore[arg-type]
    rng = np.random.default_rng(11)
    errors = []
    for _ in range(n_frames):
        frame = _render(
            world, cal, _random_pose(world, rng), rng, pixel_noise=pixel_noise, lighting=lighting
        )
        detections = extractor.extract(frame.image_bgr)
        for truth in frame.truth:
            det = detections[truth.name]
            if not truth.visible:
                assert not det.visible and det.bearing_rad is None, (truth, det)
            elif truth.occluded_fraction == 0.0:
                assert det.visible and det.bearing_rad is not None, (truth, det)
                assert det.n_blobs == 1 and det.confidence > 0.5, det
                errors.append(_err_deg(det.bearing_rad, truth.bearing_drawn_rad))
    assert len(errors) > 2 * n_frames
    return errors


@pytest.mark.parametrize("method", ["profile", "components"])
@pytest.mark.parametrize("model", MODELS)
def test_clean_view_rms_error_is_below_half_a_degree(model: str, method: str) -> None:
    errors = _clean_view_errors(model, method, pixel_noise=2.0, lighting=None, n_frames=60)
    rms = math.sqrt(float(np.mean(np.square(errors))))
    print(f"\n{model} {method} 255x176 clean: RMS {rms:.3f} deg, max {max(map(abs, errors)):.3f}")
    assert rms <= 0.5


@pytest.mark.parametrize("model", MODELS)
def test_pixel_noise_and_lighting_changes(model: str) -> None:
    errors = _clean_view_errors(model, "profile", pixel_noise=8.0, lighting=BAD_LIGHT, n_frames=60)
    rms = math.sqrt(float(np.mean(np.square(errors))))
    print(f"\n{model} 255x176 noise 8 + lighting: RMS {rms:.3f} deg")
    assert rms <= 0.5


def _facing(world: SimWorld, name: str, xy: tuple[float, float], bearing_rad: float) -> Pose:
    """Pose at ``xy`` whose heading puts landmark ``name`` at ``bearing_rad``."""
    lm = world.landmarks[world.names.index(name)]
    return (*xy, math.atan2(lm.y - xy[1], lm.x - xy[0]) - bearing_rad)


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("offset_deg", [-1.5, -0.4, 0.0, 0.7, 1.2])
def test_landmark_straddling_the_seam(model: str, offset_deg: float) -> None:
    world, cal = _paper_world(), CALIBRATIONS[model]
    pose = _facing(world, "L1", (0.52, 0.34), math.pi + math.radians(offset_deg))
    frame = _render(world, cal, pose, np.random.default_rng(2))
    truth = frame.landmark("L1")
    assert truth.half_width_rad > math.radians(1.5)  # so the offsets above straddle +-pi
    det = BearingExtractor(cal, _catalog(world)).extract(frame.image_bgr)["L1"]
    assert det.visible and det.n_blobs == 1 and det.bearing_rad is not None
    assert abs(_err_deg(det.bearing_rad, truth.bearing_drawn_rad)) < 0.5
    bin_rad = 2 * math.pi / (WIDTH if model == "unwrapped" else 90)
    assert abs(det.width_rad - 2 * truth.half_width_rad) <= 2 * bin_rad


@pytest.mark.parametrize("model", MODELS)
def test_absent_and_fully_occluded_landmarks_have_no_bearing(model: str) -> None:
    world, cal = _paper_world(), CALIBRATIONS[model]
    l1, l3 = (world.xy_world[world.names.index(n)] for n in ("L1", "L3"))
    behind_l3 = l3 + 0.08 * (l3 - l1) / np.linalg.norm(l3 - l1)  # L3 hides L1
    pose = (float(behind_l3[0]), float(behind_l3[1]), 0.3)
    frame = _render(world, cal, pose, np.random.default_rng(4), pixel_noise=6.0, lighting=BAD_LIGHT)
    assert not frame.landmark("L1").visible
    catalog = [*_catalog(world), LandmarkSpec("ghost", "magenta")]
    dets = BearingExtractor(cal, catalog).extract(frame.image_bgr)
    for name in ("L1", "ghost"):
        det = dets[name]
        assert det == Detection(name, False, None, 0.0, 0.0, det.n_pixels, 0, det.reason)
        assert det.reason
    assert dets["L3"].visible


@pytest.mark.parametrize("model", MODELS)
def test_partially_occluded_landmark_bearing_is_its_visible_part(model: str) -> None:
    paper = _paper_world()
    near = Landmark("L3", 0.5, 0.42, "blue")
    world = SimWorld(paper.arena, (Landmark("L1", 0.5, 0.5, "red"), near))
    cal = CALIBRATIONS[model]
    # step sideways until L3 (7 cm away) hides about half of L1 (15 cm away): sim geometry
    poses = [(0.5 + d, 0.35, 0.3) for d in np.linspace(0.0, 0.02, 201)]
    pose = min(poses, key=lambda p: abs(world.occluded_fractions(p)[0] - 0.5))
    frame = _render(world, cal, pose, np.random.default_rng(6))
    t1, t3 = frame.landmark("L1"), frame.landmark("L3")
    assert 0.2 < t1.occluded_fraction < 0.8
    # visible part of L1: its interval minus L3's
    rel = math.remainder(t3.bearing_drawn_rad - t1.bearing_drawn_rad, 2 * math.pi)
    lo, hi = -t1.half_width_rad, t1.half_width_rad
    if rel > 0:
        hi = min(hi, rel - t3.half_width_rad)
    else:
        lo = max(lo, rel + t3.half_width_rad)
    expected = t1.bearing_drawn_rad + (lo + hi) / 2
    det = BearingExtractor(cal, _catalog(world), min_pixels=6).extract(frame.image_bgr)["L1"]
    assert det.visible and det.bearing_rad is not None
    assert abs(_err_deg(det.bearing_rad, expected)) < 0.5
    assert det.width_rad < 2 * t1.half_width_rad


@pytest.mark.parametrize("method", ["profile", "components"])
@pytest.mark.parametrize("model", MODELS)
def test_second_blob_of_the_same_colour_is_reported_not_averaged(model: str, method: str) -> None:
    paper = _paper_world()
    twin = Landmark("L1b", 0.85, 0.45, "red")
    world = SimWorld(paper.arena, (*paper.landmarks, twin))
    cal = CALIBRATIONS[model]
    pose: Pose = (0.5, 0.4, 0.2)
    frame = _render(world, cal, pose, np.random.default_rng(8))
    l1, l1b = frame.landmark("L1"), frame.landmark("L1b")
    assert l1.range_m < l1b.range_m and l1.occluded_fraction == l1b.occluded_fraction == 0.0
    extractor = BearingExtractor(cal, _catalog(paper), method=method)  # type: ignore[arg-type]
    det = extractor.extract(frame.image_bgr)["L1"]
    assert det.n_blobs == 2 and det.bearing_rad is not None and det.second_bearing_rad is not None
    assert abs(_err_deg(det.bearing_rad, l1.bearing_drawn_rad)) < 0.5  # the larger (nearer) one
    assert abs(_err_deg(det.second_bearing_rad, l1b.bearing_drawn_rad)) < 0.5
    alone = extractor.extract(_render(paper, cal, pose, np.random.default_rng(8)).image_bgr)["L1"]
    assert alone.n_blobs == 1 and alone.second_bearing_rad is None
    assert det.confidence < 0.8 * alone.confidence


@pytest.mark.parametrize("model", MODELS)
def test_components_and_profile_agree_on_clean_frames(model: str) -> None:
    world, cal = _paper_world(), CALIBRATIONS[model]
    by_profile = BearingExtractor(cal, _catalog(world))
    by_components = BearingExtractor(cal, _catalog(world), method="components")
    rng = np.random.default_rng(12)
    for _ in range(10):
        image = _render(world, cal, _random_pose(world, rng), rng).image_bgr
        assert by_profile.extract(image) == by_components.extract(image)


@pytest.mark.parametrize("model", MODELS)
def test_png_round_trip_gives_the_same_bearings(model: str) -> None:
    world, cal = _paper_world(), CALIBRATIONS[model]
    extractor = BearingExtractor(cal, _catalog(world))
    image = _render(
        world, cal, (0.3, 0.3, 1.0), np.random.default_rng(3), lighting=BAD_LIGHT
    ).image_bgr
    ok, png = cv2.imencode(".png", image)
    assert ok
    assert extractor.extract(decode_frame(png.tobytes(), "png")) == extractor.extract(image)
    raw = decode_frame(image.tobytes(), "bgr8", width=WIDTH, height=HEIGHT)
    assert extractor.extract(raw) == extractor.extract(image)


@pytest.mark.parametrize("model", MODELS)
def test_batch_equals_frame_by_frame(model: str) -> None:
    world, cal = _paper_world(), CALIBRATIONS[model]
    extractor = BearingExtractor(cal, _catalog(world))
    rng = np.random.default_rng(13)
    frames = [_render(world, cal, _random_pose(world, rng), rng).image_bgr for _ in range(9)]
    one_by_one = [extractor.extract(f) for f in frames]
    assert extractor.extract_batch(frames) == one_by_one
    assert extractor.extract_batch(np.stack(frames)) == one_by_one
    assert extractor.extract_batch([]) == []


@pytest.mark.parametrize("model", MODELS)
def test_masks_cover_the_landmarks(model: str) -> None:
    world, cal = _paper_world(), CALIBRATIONS[model]
    frame = _render(world, cal, (0.52, 0.34, 0.0), np.random.default_rng(1))
    masks = BearingExtractor(cal, _catalog(world)).masks(frame.image_bgr)
    assert list(masks) == list(world.names)
    for truth in frame.truth:
        mask = masks[truth.name]
        assert mask.shape == (HEIGHT, WIDTH) and mask.dtype == np.bool_
        ys, xs = np.nonzero(mask)
        if isinstance(cal, UnwrappedCalibration):
            bearings = cal.bearing_of_column(xs + 0.5)
        else:
            bearings = cal.bearing_of_pixel(xs + 0.5, ys + 0.5)
        off = np.abs(np.remainder(bearings - truth.bearing_drawn_rad + np.pi, 2 * np.pi) - np.pi)
        assert ys.size > 0 and off.max() <= truth.half_width_rad + 2 * math.pi / 90


@pytest.mark.parametrize("model", MODELS)
def test_extract_with_masks_is_extract_and_masks(model: str) -> None:
    world, cal = _paper_world(), CALIBRATIONS[model]
    extractor = BearingExtractor(cal, _catalog(world))
    rng = np.random.default_rng(21)
    for _ in range(3):
        image = _render(world, cal, _random_pose(world, rng), rng).image_bgr
        detections, masks = extractor.extract_with_masks(image)
        assert detections == extractor.extract(image)
        expected = extractor.masks(image)
        assert list(masks) == list(expected)
        assert all(np.array_equal(masks[n], expected[n]) for n in expected)
        assert any(m.any() for m in masks.values())


@pytest.mark.parametrize(
    ("image", "message"),
    [
        (np.zeros((HEIGHT, WIDTH, 3), np.float32), "uint8 BGR, got dtype float32"),
        (np.zeros((HEIGHT, WIDTH), np.uint8), r"image is greyscale \(shape \(176, 255\)\)"),
        (np.zeros((HEIGHT, WIDTH, 4), np.uint8), r"shape \(H, W, 3\)"),
        (np.zeros((HEIGHT, WIDTH, 4), np.uint8), r"got \(176, 255, 4\)"),
        (np.zeros((WIDTH, HEIGHT, 3), np.uint8), "is 176x255 .* calibration is 255x176"),
        ([[0, 0, 0]], "numpy array, got list"),
    ],
)
@pytest.mark.parametrize("model", MODELS)
def test_bad_images_raise_one_clear_line(model: str, image: object, message: str) -> None:
    extractor = BearingExtractor(CALIBRATIONS[model], _catalog(_paper_world()))
    calls = (
        extractor.extract,
        extractor.masks,
        extractor.extract_with_masks,
        lambda im: extractor.extract_batch([im]),
    )
    for call in calls:
        with pytest.raises(ImageError, match=message) as info:
            call(image)  # type: ignore[operator]
        assert "\n" not in str(info.value)
