"""Coded (banded) landmarks on simulator frames: decoding, seam, partial occlusion, many codes.

Truth is what the renderer drew (``bearing_drawn_rad``); figures are printed (``-s``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.typing import NDArray

from data_schemas.calibration import Calibration, UnwrappedCalibration, default_omni
from data_schemas.session import LandmarkSpec
from pipeline.bearings import BearingExtractor, LandmarkCatalogError
from pipeline.bearings.bands import BandDecoder
from pipeline.bearings.layout import make_layout
from recorder.sim.coded import coded_landmarks
from recorder.sim.render import Lighting, RenderedFrame, render_panorama
from recorder.sim.world import Arena, Landmark, Pose, SimWorld

CALIBRATIONS: dict[str, Calibration] = {
    "unwrapped": UnwrappedCalibration(480, 120),
    "omni": default_omni(320, 320),
}
MODELS = list(CALIBRATIONS)
ARENA = Arena(1.5, 1.0)


def _spec(lm: Landmark) -> LandmarkSpec:
    return LandmarkSpec(lm.name, lm.color, bands=lm.bands)


def _render(world: SimWorld, cal: Calibration, pose: Pose, seed: int) -> RenderedFrame:
    return render_panorama(
        pose,
        world,
        cal,
        np.random.default_rng(seed),
        bearing_noise_rad=0.0,
        vision_error_rad=0.05,
        lighting=Lighting(),
    )


def _err_deg(a_rad: float, b_rad: float) -> float:
    return math.degrees(math.remainder(a_rad - b_rad, 2 * math.pi))


def _facing(lm: Landmark, xy: tuple[float, float], bearing_rad: float) -> Pose:
    """Pose at ``xy`` whose heading puts ``lm`` at ``bearing_rad``."""
    return (*xy, math.atan2(lm.y - xy[1], lm.x - xy[0]) - bearing_rad)


CODES = [
    Landmark("A", 1.2, 0.5, None, bands=("magenta", "yellow")),
    Landmark("B", 0.3, 0.2, None, bands=("yellow", "magenta")),  # A reversed
    Landmark("C", 0.3, 0.8, None, bands=("cyan", "red", "green")),
    Landmark("D", 1.1, 0.85, "blue"),  # single colour beside codes
]


@pytest.mark.parametrize("model", MODELS)
def test_codes_are_decoded_in_order_and_told_apart(model: str) -> None:
    world, cal = SimWorld(ARENA, tuple(CODES)), CALIBRATIONS[model]
    ghosts = [
        LandmarkSpec("G1", None, bands=("magenta", "cyan")),
        LandmarkSpec("G2", None, bands=("red", "green")),  # a part of C's code
        LandmarkSpec("G3", "yellow"),  # a colour seen only as bands
    ]
    extractor = BearingExtractor(cal, [*map(_spec, CODES), *ghosts])
    rng = np.random.default_rng(40)
    errors = []
    for i in range(12):
        pose = (rng.uniform(0.5, 1.0), rng.uniform(0.35, 0.65), rng.uniform(-math.pi, math.pi))
        frame = _render(world, cal, pose, i)
        found = extractor.extract(frame.image_bgr)
        for truth in frame.truth:
            det = found[truth.name]
            assert det.n_blobs <= 1, det
            if truth.visible and truth.occluded_fraction == 0.0:
                assert det.visible and det.bearing_rad is not None, (truth, det)
                errors.append(_err_deg(det.bearing_rad, truth.bearing_drawn_rad))
        for ghost in ("G1", "G2", "G3"):
            assert not found[ghost].visible and found[ghost].n_blobs == 0, found[ghost]
    assert len(errors) >= 40
    rms = math.sqrt(float(np.mean(np.square(errors))))
    print(f"\n{model}: {len(errors)} coded/plain views, RMS {rms:.3f} deg")
    assert rms < 0.3 and max(map(abs, errors)) < 1.0


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("offset_deg", [-1.5, -0.3, 0.0, 0.8])
def test_code_straddling_the_seam(model: str, offset_deg: float) -> None:
    code = Landmark("A", 0.75, 0.5, None, radius_m=0.02, bands=("blue", "yellow", "red"))
    world, cal = SimWorld(ARENA, (code,)), CALIBRATIONS[model]
    pose = _facing(code, (0.5, 0.5), math.pi + math.radians(offset_deg))
    frame = _render(world, cal, pose, 3)
    truth = frame.landmark("A")
    assert truth.half_width_rad > math.radians(2.0)  # the offsets above straddle +-pi
    sightings = BearingExtractor(cal, [_spec(code)]).extract_classes(frame.image_bgr)
    (blob,) = sightings["blue-yellow-red"].blobs  # one blob, not one per side of the seam
    assert abs(_err_deg(blob.bearing_rad, truth.bearing_drawn_rad)) < 0.3
    assert abs(blob.width_rad - 2 * truth.half_width_rad) < math.radians(2.0)


def _band_pixels(image: NDArray[np.uint8], cal: Calibration, color: str) -> NDArray[np.bool_]:
    """Pixels the extractor classifies as ``color``."""
    return BearingExtractor(cal, [LandmarkSpec("x", color)]).masks(image)["x"]


def _pixel_bearings(cal: Calibration) -> NDArray[np.float64]:
    ys, xs = np.mgrid[0 : cal.height, 0 : cal.width] + 0.5
    if isinstance(cal, UnwrappedCalibration):
        return cal.bearing_of_column(xs)
    return cal.bearing_of_pixel(xs, ys)


def _elevation_rank(cal: Calibration) -> NDArray[np.float64]:
    """Larger = higher in the view: minus the row (unwrapped), the radius (omni)."""
    ys, xs = np.mgrid[0 : cal.height, 0 : cal.width] + 0.5
    if isinstance(cal, UnwrappedCalibration):
        return -ys
    return np.hypot(xs - cal.cx, ys - cal.cy)


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("hide", ["lower half of the bottom band", "bottom band on one side"])
def test_one_band_partly_occluded_is_still_read(model: str, hide: str) -> None:
    """Something grey in front of part of one band: the code is read, the bearing is that of
    the visible part (unchanged when only the band's height is cut)."""
    code = Landmark("A", 0.9, 0.5, None, radius_m=0.025, bands=("magenta", "cyan", "yellow"))
    world, cal = SimWorld(ARENA, (code,)), CALIBRATIONS[model]
    pose = _facing(code, (0.5, 0.5), 0.6)
    frame = _render(world, cal, pose, 5)
    truth = frame.landmark("A")
    image = frame.image_bgr.copy()
    bottom = _band_pixels(image, cal, "yellow")
    assert bottom.sum() > 20
    if hide == "lower half of the bottom band":
        rank = _elevation_rank(cal)
        hidden = bottom & (rank < np.median(rank[bottom]))
    else:
        off = np.remainder(_pixel_bearings(cal) - truth.bearing_drawn_rad + np.pi, 2 * np.pi)
        hidden = bottom & (off - np.pi < -0.2 * truth.half_width_rad)
    image[hidden] = (150, 157, 163)  # the wall's grey
    extractor = BearingExtractor(cal, [_spec(code)])
    det = extractor.extract(image)["A"]
    assert det.visible and det.bearing_rad is not None, det
    err = _err_deg(det.bearing_rad, truth.bearing_drawn_rad)
    half_deg = math.degrees(truth.half_width_rad)
    print(f"\n{model}, {hide}: error {err:+.3f} deg, half-width {half_deg:.2f}")
    if hide == "lower half of the bottom band":
        assert abs(err) < 0.3
    else:  # visible part: the whole landmark minus a fifth of one band's side
        assert abs(err) < 0.5 * half_deg
    # the whole bottom band hidden: only a two-band part is seen, which is not this code
    image[bottom] = (150, 157, 163)
    assert not extractor.extract(image)["A"].visible


def test_twenty_coded_landmarks_in_a_3_by_2_m_arena() -> None:
    """The issue's arena: 20 codes, unwrapped 960x160; every clean view read, none invented."""
    arena = Arena(3.0, 2.0)
    docs = coded_landmarks(3.0, 2.0, 20, np.random.default_rng(7))
    landmarks = tuple(
        Landmark(d["name"], d["x"], d["y"], None, bands=tuple(d["bands"])) for d in docs
    )
    world, cal = SimWorld(arena, landmarks), UnwrappedCalibration(960, 160)
    extractor = BearingExtractor(cal, [_spec(lm) for lm in landmarks])
    rng = np.random.default_rng(41)
    views = hits = wrong = invented = 0
    errors = []
    for i in range(15):
        while True:
            pose = (rng.uniform(0.2, 2.8), rng.uniform(0.2, 1.8), rng.uniform(-math.pi, math.pi))
            if np.hypot(*(world.xy_world - pose[:2]).T).min() > 0.12:
                break
        frame = _render(world, cal, pose, 100 + i)
        found = extractor.extract(frame.image_bgr)
        for truth in frame.truth:
            det = found[truth.name]
            if not truth.visible:
                invented += det.visible
            elif truth.occluded_fraction == 0.0:
                views += 1
                if det.visible and det.bearing_rad is not None:
                    err = _err_deg(det.bearing_rad, truth.bearing_drawn_rad)
                    hits += abs(err) < 1.0
                    wrong += abs(err) >= 1.0
                    errors.append(err)
            elif det.visible and det.bearing_rad is not None:  # partly hidden: its visible part
                wrong += (
                    abs(_err_deg(det.bearing_rad, truth.bearing_drawn_rad))
                    > math.degrees(truth.half_width_rad) + 0.5
                )
    rms = math.sqrt(float(np.mean(np.square(errors))))
    print(
        f"\n20 codes 960x160: {hits}/{views} clean views read, wrong {wrong}, invented {invented}"
    )
    print(f"  RMS {rms:.3f} deg")
    assert hits >= 0.98 * views and wrong == 0 and invented == 0
    assert rms < 0.2


def test_single_colour_landmarks_are_not_taken_from_bands() -> None:
    """A plain yellow landmark is not the yellow band of a code beside it, and vice versa."""
    cal = CALIBRATIONS["unwrapped"]
    code = Landmark("A", 1.2, 0.5, None, bands=("magenta", "yellow"))
    plain = Landmark("Y", 0.3, 0.5, "yellow")
    world = SimWorld(ARENA, (code, plain))
    extractor = BearingExtractor(cal, [_spec(code), _spec(plain)])
    frame = _render(world, cal, (0.75, 0.55, 0.0), 9)
    found = extractor.extract(frame.image_bgr)
    for name in ("A", "Y"):
        assert found[name].n_blobs == 1 and found[name].bearing_rad is not None
        err = _err_deg(found[name].bearing_rad, frame.landmark(name).bearing_drawn_rad)
        assert abs(err) < 0.5, name
    # with the plain landmark gone, its class sees nothing (the code's band is not it)
    alone = _render(SimWorld(ARENA, (code,)), cal, (0.75, 0.55, 0.0), 9)
    assert extractor.extract(alone.image_bgr)["Y"].n_blobs == 0


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        (LandmarkSpec("L9", None, bands=("red",)), "two or more bands"),
        (LandmarkSpec("L9", None, bands=("red", "red")), "adjacent bands"),
        (LandmarkSpec("L9", None, bands=("red", "teal")), "unknown colour 'teal'"),
        (
            LandmarkSpec("L9", None, (0, 90, 50), (10, 255, 255), bands=("red", "blue")),
            "is coded: give 'hsv' as a list of 2 boxes",
        ),
        (
            LandmarkSpec(
                "L9", None, bands=("red", "blue"), band_hsv=(((0, 90, 50), (10, 255, 255)),)
            ),
            "2 bands but 1 HSV boxes",
        ),
        (
            LandmarkSpec(
                "L9", None, bands=("red", "blue"), band_hsv=(((0, 90, 50), (10, 255)),) * 2
            ),
            "need 3 values",
        ),
        (
            LandmarkSpec("L9", "red", band_hsv=(((0, 90, 50), (10, 255, 255)),) * 2),
            "one colour: give 'hsv' one box",
        ),
    ],
)
def test_bad_codes_raise_one_clear_line(spec: LandmarkSpec, message: str) -> None:
    with pytest.raises(LandmarkCatalogError, match=message) as info:
        BearingExtractor(UnwrappedCalibration(32, 8), [spec])
    assert "\n" not in str(info.value) and "L9" in str(info.value)


@pytest.mark.parametrize("model", MODELS)
def test_each_band_is_found_by_its_own_box(model: str) -> None:
    """A code's per-band boxes replace its colours' defaults: a yellow band's box moved to cyan
    hues (80..100) loses the code; one around yellow (24..36) reads it; a single-colour
    yellow landmark keeps the default yellow box all along."""
    cal = CALIBRATIONS[model]
    code = Landmark("A", 1.2, 0.5, None, bands=("magenta", "yellow"))
    plain = Landmark("Y", 0.3, 0.5, "yellow")
    frame = _render(SimWorld(ARENA, (code, plain)), cal, (0.75, 0.55, 0.0), 9)
    magenta = ((140, 90, 50), (160, 255, 255))

    def found(yellow_box: tuple[tuple[int, int, int], tuple[int, int, int]]) -> dict:  # type: ignore[type-arg]
        spec = LandmarkSpec("A", None, bands=code.bands, band_hsv=(magenta, yellow_box))
        return BearingExtractor(cal, [spec, _spec(plain)]).extract(frame.image_bgr)

    off = found(((80, 90, 50), (100, 255, 255)))
    assert off["A"].bearing_rad is None and off["Y"].bearing_rad is not None
    on = found(((24, 90, 50), (36, 255, 255)))
    err = _err_deg(on["A"].bearing_rad or 99.0, frame.landmark("A").bearing_drawn_rad)
    assert abs(err) < 0.5 and on["Y"].bearing_rad is not None


@pytest.mark.parametrize("model", MODELS)
def test_every_blob_of_a_shared_class_is_returned_and_none_is_guessed(model: str) -> None:
    """Two red landmarks and two of one code: each class lists both blobs with bearing and
    extent; no landmark of such a class gets a bearing (which one would it be?)."""
    cal = CALIBRATIONS[model]
    landmarks = (
        Landmark("R1", 1.2, 0.3, "red"),
        Landmark("R2", 0.3, 0.7, "red"),
        Landmark("C1", 1.2, 0.8, None, bands=("green", "magenta")),
        Landmark("C2", 0.25, 0.25, None, bands=("green", "magenta")),
        Landmark("U", 0.75, 0.9, "blue"),
    )
    world = SimWorld(ARENA, landmarks)
    extractor = BearingExtractor(cal, [_spec(lm) for lm in landmarks])
    frame = _render(world, cal, (0.75, 0.5, 0.4), 11)
    sightings = extractor.extract_classes(frame.image_bgr)
    assert set(sightings) == {"red", "green-magenta", "blue"}
    for label, names in (("red", ("R1", "R2")), ("green-magenta", ("C1", "C2"))):
        seen = sightings[label]
        assert seen.landmarks == names and len(seen.blobs) == 2
        for name in names:
            truth = frame.landmark(name)
            best = min(abs(_err_deg(b.bearing_rad, truth.bearing_drawn_rad)) for b in seen.blobs)
            assert best < 0.5
        assert all(b.width_rad > 0 and b.n_pixels >= extractor.min_pixels for b in seen.blobs)
    found = extractor.extract(frame.image_bgr)
    for name in ("R1", "R2", "C1", "C2"):
        det = found[name]
        assert det.ambiguous and not det.visible and det.bearing_rad is None
        assert det.n_blobs == 2 and len(det.blobs) == 2 and "ambiguous" in det.reason
    assert found["U"].visible and not found["U"].ambiguous and len(found["U"].blobs) == 1


def _decoder(width: int, codes: list[tuple[int, ...]], **kw: int) -> BandDecoder:
    """Decoder over an unwrapped layout; colours 0..5 are red..magenta (hues 0, 30, ... 150)."""
    layout = make_layout(UnwrappedCalibration(width, 40))
    return BandDecoder(
        layout,
        [0.0, 30.0, 60.0, 90.0, 120.0, 150.0],
        codes,
        min_pixels=kw.get("min_pixels", 4),
        max_gap_bins=kw.get("max_gap_bins", 1),
    )


def _paint(labels: NDArray[np.uint8], cols: list[int], bands: list[tuple[int, int, int]]) -> None:
    """Label rows ``a..b-1`` with colour ``c`` (0-based) in ``cols``, for each (c, a, b)."""
    for c, a, b in bands:
        labels[a:b, cols] = c + 1


def test_decoder_reads_codes_on_a_synthetic_grid() -> None:
    """Order matters, blends and short gaps are bridged, a part of a code never anchors a blob,
    runs join across the seam, the largest blob comes first."""
    mg, ym, cy = (5, 1), (1, 5), (3, 1)  # magenta-yellow, yellow-magenta, cyan-yellow
    decoder = _decoder(100, [mg, ym, cy])
    labels = np.zeros((40, 100), np.uint8)
    _paint(labels, [10, 11, 12], [(5, 5, 15), (0, 15, 16), (1, 16, 26)])  # red blend between
    _paint(labels, [13], [(5, 5, 15), (1, 18, 26)])  # a 3-row gap in the bottom band's top
    _paint(labels, [14], [(5, 5, 15)])  # the bottom band hidden here: partly read, extends it
    _paint(labels, [40], [(5, 5, 15)])  # a part alone: no blob
    _paint(labels, [98, 99, 0, 1], [(3, 2, 10), (1, 10, 18)])  # cyan-yellow across the seam
    _paint(labels, [60, 61], [(3, 2, 6), (1, 6, 10)])  # a smaller cyan-yellow
    out = decoder.decode(decoder.grid(labels))
    (blob_mg,), largest = out[0]
    assert blob_mg.width_rad == pytest.approx(5 * 2 * math.pi / 100)  # columns 10..14
    assert blob_mg.n_pixels == 3 * 21 + 18 + 10 and largest == blob_mg.n_pixels
    assert out[1] == ([], 0)  # the reversed code is not there
    seam, small = out[2][0]
    assert seam.n_pixels == 4 * 16 and small.n_pixels == 2 * 8
    layout = make_layout(UnwrappedCalibration(100, 40))
    centre = math.atan2(
        float(layout.bin_sin[[98, 99, 0, 1]].sum()), float(layout.bin_cos[[98, 99, 0, 1]].sum())
    )
    assert math.remainder(seam.bearing_rad - centre, 2 * math.pi) == pytest.approx(0, abs=1e-9)
    assert seam.width_rad == pytest.approx(4 * 2 * math.pi / 100)


def test_decoder_keeps_apart_what_a_gap_separates() -> None:
    decoder = _decoder(100, [(5, 1)], max_gap_bins=1)
    labels = np.zeros((40, 100), np.uint8)
    _paint(labels, [20, 21, 23, 24], [(5, 5, 15), (1, 15, 25)])  # one empty column: one blob
    _paint(labels, [50, 51, 54, 55], [(5, 5, 15), (1, 15, 25)])  # two empty columns: two
    blobs, _ = decoder.decode(decoder.grid(labels))[0]
    assert sorted(round(b.width_rad / (2 * math.pi / 100)) for b in blobs) == [2, 2, 5]


def test_a_sliver_between_complementary_colours_is_a_blend() -> None:
    """Red over cyan meet through any hue (here yellow): the sliver is not a band."""
    red_yellow, red_cyan = (0, 1), (0, 3)
    decoder = _decoder(100, [red_yellow, red_cyan])
    labels = np.zeros((40, 100), np.uint8)
    _paint(labels, [30, 31, 32], [(0, 5, 15), (1, 15, 16), (3, 16, 26)])
    out = decoder.decode(decoder.grid(labels))
    assert out[0] == ([], 0)
    (blob,), _ = out[1]
    assert blob.n_pixels == 3 * 21  # its span, the blended row included


def test_codes_read_over_the_same_bearings_are_both_dropped() -> None:
    """Columns that mix two landmarks can read as two codes at once: neither is trusted."""
    cal = UnwrappedCalibration(400, 40)
    specs = [
        LandmarkSpec("A", None, bands=("red", "green")),
        LandmarkSpec("B", None, bands=("red", "cyan")),
    ]
    extractor = BearingExtractor(cal, specs)
    image = np.full((40, 400, 3), 160, np.uint8)
    red, green, cyan = ((0, 0, 220), (0, 200, 0), (220, 220, 0))
    image[5:15, 100:104] = red
    image[15:25, [100, 102]] = green  # the same red top above bottoms that alternate
    image[15:25, [101, 103]] = cyan
    image[5:15, 300:304] = red  # and a clean red-cyan elsewhere
    image[15:25, 300:304] = cyan
    found = extractor.extract_classes(image)
    assert found["red-green"].blobs == ()
    (only,) = found["red-cyan"].blobs
    assert abs(math.degrees(only.bearing_rad - cal.bearing_of_column(302.0))) < 0.5


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("offset_deg", [1.6, 1.8, 2.2])
def test_two_landmarks_edge_to_edge_are_not_their_colours_code(
    model: str, offset_deg: float
) -> None:
    # a blue landmark 0.64 m away and a yellow one 0.72 m away, a little to its left: where
    # their edges meet, rays (omni) cross blue then yellow, the code of L8 (blue over yellow)
    a = math.radians(150.0)
    b = a + math.radians(offset_deg)
    x0, y0 = 1.0, 0.2
    blue = Landmark("L3", x0 + 0.64 * math.cos(a), y0 + 0.64 * math.sin(a), "blue")
    yellow = Landmark("L4", x0 + 0.72 * math.cos(b), y0 + 0.72 * math.sin(b), "yellow")
    code = Landmark("L8", 0.2, 0.9, None, bands=("blue", "yellow"))
    world, cal = SimWorld(Arena(1.5, 1.5), (blue, yellow, code)), CALIBRATIONS[model]
    pose = (x0, y0, 0.0)
    det = BearingExtractor(cal, [_spec(blue), _spec(yellow), _spec(code)]).extract(
        _render(world, cal, pose, 3).image_bgr
    )
    for lm in (blue, yellow, code):
        truth = math.atan2(lm.y - y0, lm.x - x0)
        got = det[lm.name].bearing_rad
        assert got is not None, (lm.name, det)
        assert abs(_err_deg(got, truth)) < 0.5, (lm.name, math.degrees(got), math.degrees(truth))
