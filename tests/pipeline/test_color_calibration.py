"""Colour under real light: boxes learned from marked frames (``bslam calibrate colors``), the
size gate, and per-band boxes in use.

The scene (the issue's goal): a pinhole camera (640x480, 60 deg, barrel distortion) in a 3 x 2 m
arena, four single-colour landmarks and a three-band code, an olive floor that the default
yellow box takes and a pink wall that the default red box takes, a warm colour cast, and a
brightness drawn in x0.5..1.5 per frame. Marks come from the renderer's truth (the bearing and
band heights it drew, projected by the simulator's own lens), as a user would click them.
Truth: what the renderer drew; a detection is right within eps = 3 deg of the drawn bearing.
"""

from __future__ import annotations

import collections
import functools
import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from data_schemas.errors import ImageError
from data_schemas.session import LandmarkSpec
from pipeline.bearings import BearingExtractor
from pipeline.bearings.learn_colors import ColorMark, ColorMarkError, learn_catalog_boxes
from pipeline.bearings.pinhole import field_of_view_rad
from recorder.session import load_landmark_file
from recorder.sim.lens import project
from recorder.sim.render import CAMERA_HEIGHT_M, Backdrop, Lighting, RenderedFrame, render_panorama
from recorder.sim.scenario import simulated_pinhole
from recorder.sim.world import Arena, Landmark, SimWorld
from replay.cli import cli

DEG = math.pi / 180.0
EPS = 3.0 * DEG
LANDMARKS = (
    Landmark("R", 0.4, 0.4, "red", radius_m=0.03, height_m=0.2),
    Landmark("Y", 2.6, 0.4, "yellow", radius_m=0.03, height_m=0.2),
    Landmark("M", 2.6, 1.6, "magenta", radius_m=0.03, height_m=0.2),
    Landmark(
        "C", 0.4, 1.6, None, radius_m=0.03, height_m=0.3, bands=("green", "magenta", "yellow")
    ),
    Landmark("B", 1.5, 1.8, "blue", radius_m=0.03, height_m=0.2),
)
WORLD = SimWorld(Arena(3.0, 2.0), LANDMARKS)
#: olive floor (H 27, S 130: in the default yellow box), pink wall (H 172, S 100: default red)
BACKDROP = Backdrop(floor_bgr=(69.0, 133.0, 140.0), wall_bgr=(143.0, 122.0, 200.0))
CAL = simulated_pinhole(640, 480, 60 * DEG, (-0.1, 0.02, 0.0, 0.0, 0.0))
CAST_BGR = np.array([0.85, 1.0, 1.15], np.float32)  # warm light
RANGE_M = (0.3, 3.6)


def _catalog() -> list[LandmarkSpec]:
    return [
        LandmarkSpec(
            lm.name, lm.color, bands=lm.bands, width_m=2 * lm.radius_m, height_m=lm.height_m
        )
        for lm in LANDMARKS
    ]


def _frame(rng: np.random.Generator) -> tuple[RenderedFrame, np.ndarray]:
    """A frame from a random pose at least 35 cm from every landmark, under the scene's light."""
    while True:
        x, y = rng.uniform(0.3, 2.7), rng.uniform(0.3, 1.7)
        if min(math.hypot(x - lm.x, y - lm.y) for lm in LANDMARKS) > 0.35:
            break
    pose = (x, y, rng.uniform(-math.pi, math.pi))
    frame = render_panorama(
        pose, WORLD, CAL, rng, bearing_noise_rad=0.0, vision_error_rad=0.05,
        lighting=Lighting(), backdrop=BACKDROP,
    )  # fmt: skip
    gain = rng.uniform(0.5, 1.5)
    image = np.clip(frame.image_bgr.astype(np.float32) * (gain * CAST_BGR), 0, 255)
    return frame, image.astype(np.uint8)


def _pixel(bearing_rad: float, elevation_rad: float) -> tuple[float, float]:
    """Where the simulator's lens puts a ray (continuous pixel coordinates)."""
    xn = -math.tan(bearing_rad)
    yn = -math.tan(elevation_rad) * math.hypot(xn, 1.0)
    u, v = project(CAL, np.array([xn]), np.array([yn]))
    return float(u[0]), float(v[0])


@functools.cache
def _view() -> tuple[float, float]:
    return field_of_view_rad(CAL)


def _whole_in_view(frame: RenderedFrame) -> dict[str, bool]:
    lo, hi = _view()
    return {
        t.name: t.bearing_drawn_rad - t.half_width_rad > lo + DEG
        and t.bearing_drawn_rad + t.half_width_rad < hi - DEG
        for t in frame.truth
    }


def _marks(frame: RenderedFrame, index: int, columns: bool) -> list[ColorMark]:
    """A user's marks: a point on each band, or the columns, of each unhidden landmark."""
    out = []
    whole = _whole_in_view(frame)
    for t in frame.truth:
        lm = next(lm for lm in LANDMARKS if lm.name == t.name)
        if not t.visible or t.occluded_fraction > 0 or not whole[t.name]:
            continue
        b, half, surface = t.bearing_drawn_rad, t.half_width_rad, t.range_m - lm.radius_m
        if columns:
            left, right = _pixel(b + 0.9 * half, 0.0)[0], _pixel(b - 0.9 * half, 0.0)[0]
            out.append(ColorMark(index, t.name, columns=(math.ceil(left), math.floor(right))))
        else:
            n = len(lm.paint)
            z_m = [lm.height_m * (n - k - 0.5) / n for k in range(n)]
            points = tuple(_pixel(b, math.atan2(z - CAMERA_HEIGHT_M, surface)) for z in z_m)
            out.append(ColorMark(index, t.name, points=points))
    return out


def _marked_frames(
    seed: int, columns: bool, per_landmark: int = 2
) -> tuple[list[np.ndarray], list[ColorMark]]:
    """Frames (each landmark whole in view or absent) until each landmark is marked twice."""
    rng = np.random.default_rng(seed)
    frames: list[np.ndarray] = []
    marks: list[ColorMark] = []
    count: collections.Counter[str] = collections.Counter()
    while min(count[lm.name] for lm in LANDMARKS) < per_landmark:
        frame, image = _frame(rng)
        shown = [t.name for t in frame.truth if t.visible]
        new = _marks(frame, len(frames), columns)
        if not new or not all(_whole_in_view(frame)[n] for n in shown):
            continue
        if all(count[m.landmark] >= per_landmark for m in new):
            continue
        frames.append(image)
        marks += new
        count.update(m.landmark for m in new)
    return frames, marks


def _score(extractor: BearingExtractor, seed: int, n_frames: int) -> tuple[int, int, int]:
    """(found, views, false): views of landmarks whole in view and unhidden; found within eps;
    false: a bearing for a landmark not there, or more than eps off."""
    rng = np.random.default_rng(seed)
    found = views = false = 0
    for _ in range(n_frames):
        frame, image = _frame(rng)
        whole = _whole_in_view(frame)
        detections = extractor.extract(image)
        for t in frame.truth:
            got = detections[t.name].bearing_rad
            right = (
                got is not None
                and abs(math.remainder(got - t.bearing_drawn_rad, 2 * math.pi)) < EPS
            )
            if whole[t.name] and t.occluded_fraction == 0 and t.visible:
                views += 1
                found += right
                false += got is not None and not right
            elif got is not None and not (t.visible and right):
                false += 1
    return found, views, false


@pytest.mark.slow  # two calibrations and 240 frames of 640x480, about 15 s
@pytest.mark.parametrize("columns", [False, True], ids=["points", "columns"])
def test_calibrated_colors_find_every_landmark_and_no_false_one(columns: bool) -> None:
    """Goal: after calibration, recall >= 95 % and no false landmark (two calibration seeds,
    60 frames each); with the default boxes the same frames fail."""
    default = _score(BearingExtractor(CAL, _catalog(), range_m=RANGE_M), 5, 60)
    print(f"\ndefault boxes, size gate: found {default[0]}/{default[1]}, false {default[2]}")
    assert default[0] < 0.95 * default[1] and default[2] > 0
    for seed in (100, 300):
        frames, marks = _marked_frames(seed, columns)
        catalog, learned = learn_catalog_boxes(frames, marks, _catalog())
        assert {lb.color for lb in learned} == {"red", "yellow", "magenta", "green", "blue"}
        found, views, false = _score(BearingExtractor(CAL, catalog, range_m=RANGE_M), 5, 60)
        print(f"calibrated on {len(frames)} frames: found {found}/{views}, false {false}")
        assert views >= 40 and found >= 0.95 * views and false == 0


def test_calibrate_colors_command(tmp_path: Path) -> None:
    """``bslam calibrate colors`` writes a catalog whose boxes find the marked landmarks in a
    frame it was not given, and keep out the floor and the wall (OpenCV's inRange as oracle)."""
    frames, marks = _marked_frames(100, False, per_landmark=1)
    paths = []
    for k, image in enumerate(frames):
        paths.append(str(tmp_path / f"f{k}.png"))
        cv2.imwrite(paths[-1], image)
    doc = {
        "marks": [
            {
                "frame": f"f{m.frame}.png",
                "landmark": m.landmark,
                "points": [list(p) for p in m.points],
            }
            for m in marks
        ]
    }
    (tmp_path / "marks.json").write_text(json.dumps(doc))
    catalog = {
        "landmarks": [
            {"name": lm.name, "color": lm.color}
            if lm.color
            else {"name": lm.name, "bands": list(lm.bands)}
            for lm in LANDMARKS
        ],
        "reference": ["R", "B"],
        "vision_error_deg": 3.0,
        "range_m": list(RANGE_M),
    }
    (tmp_path / "in.json").write_text(json.dumps(catalog))
    args = ["calibrate", "colors", *paths, "--marks", str(tmp_path / "marks.json")]
    args += ["--catalog", str(tmp_path / "in.json"), "--out", str(tmp_path / "out.json")]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    assert "red: H " in result.output and "wrote" in result.output
    learned = load_landmark_file(tmp_path / "out.json")
    assert learned.range_m == RANGE_M and learned.reference == ("R", "B")
    boxes = {s.name: s for s in learned.landmarks}
    assert boxes["R"].hsv_lo is not None and len(boxes["C"].band_hsv) == 3
    lo, hi = boxes["Y"].hsv_lo, boxes["Y"].hsv_hi
    assert lo is not None and hi is not None
    for bgr, inside in (((0, 220, 253), True), ((59, 133, 161), False)):  # yellow, floor (cast)
        pixel = cv2.cvtColor(np.array([[bgr]], np.uint8), cv2.COLOR_BGR2HSV)
        assert bool(cv2.inRange(pixel, np.array(lo), np.array(hi))[0, 0]) == inside, bgr
    # the command refuses to overwrite, and says so in one line
    again = CliRunner().invoke(cli, args)
    assert again.exit_code == 1 and "exists: pass --force" in again.output


def _plain_frame() -> tuple[np.ndarray, dict[str, tuple[slice, slice]]]:
    """A 60 x 80 frame: room grey, a pink wall band, an olive floor, a red and a blue bar."""
    image = np.full((60, 80, 3), (150, 150, 150), np.uint8)
    parts = {
        "wall": (slice(20, 35), slice(0, 80)),
        "floor": (slice(45, 60), slice(0, 80)),
        "R": (slice(10, 45), slice(20, 26)),
        "B": (slice(12, 45), slice(50, 55)),
    }
    colors = {"wall": (143, 122, 200), "floor": (69, 133, 140), "R": (0, 0, 220), "B": (220, 0, 0)}
    for name, where in parts.items():
        image[where] = colors[name]
    return image, parts


def test_learned_boxes_hold_the_marks_and_keep_out_the_rest() -> None:
    image, parts = _plain_frame()
    catalog = [LandmarkSpec("R", "red"), LandmarkSpec("B", "blue"), LandmarkSpec("G", "green")]
    marks = [
        ColorMark(0, "R", points=((22.5, 15.5), (23.5, 40.5))),
        ColorMark(0, "B", columns=(50, 54)),
    ]
    specs, learned = learn_catalog_boxes([image], marks, catalog)
    hsv = cv2.cvtColor(image, cv2.COLOR_BGR2HSV)
    by_name = {s.name: s for s in specs}
    assert by_name["G"] == catalog[2]  # not marked: unchanged
    for name in ("R", "B"):
        lo, hi = by_name[name].hsv_lo, by_name[name].hsv_hi
        assert lo is not None and hi is not None
        if lo[0] > hi[0]:  # wraps through 179 -> 0
            a = cv2.inRange(hsv, np.array([lo[0], lo[1], lo[2]]), np.array([179, hi[1], hi[2]]))
            b = cv2.inRange(hsv, np.array([0, lo[1], lo[2]]), np.array([hi[0], hi[1], hi[2]]))
            mask = (a | b) > 0
        else:
            mask = cv2.inRange(hsv, np.array(lo), np.array(hi)) > 0
        assert mask[parts[name]].all(), name
        wall_alone = (parts["wall"][0], slice(30, 48))  # between the bars
        assert not mask[wall_alone].any() and not mask[parts["floor"]].any(), name
    assert [lb.color for lb in learned] == ["blue", "red"]


@pytest.mark.parametrize(
    ("marks", "message"),
    [
        ([], "no marks"),
        ([ColorMark(0, "X", points=((1.0, 1.0),))], "'X': no such landmark"),
        ([ColorMark(3, "R", points=((1.0, 1.0),))], "no frame 3"),
        ([ColorMark(0, "R", points=((99.0, 1.0),))], r"point \(99, 1\) is outside the 80x60 frame"),
        ([ColorMark(0, "R", columns=(70, 90))], "columns 70..90 are outside"),
        ([ColorMark(0, "R", columns=(2, 8))], "no row of columns 2..8 differs"),
    ],
)
def test_bad_marks_raise_one_line(marks: list[ColorMark], message: str) -> None:
    image, _ = _plain_frame()
    with pytest.raises(ColorMarkError, match=message) as info:
        learn_catalog_boxes([image], marks, [LandmarkSpec("R", "red")])
    assert "\n" not in str(info.value)


def test_greyscale_frames_cannot_teach_colours() -> None:
    image, _ = _plain_frame()
    grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    with pytest.raises(ImageError, match="greyscale"):
        learn_catalog_boxes(
            [grey], [ColorMark(0, "R", points=((22.5, 15.5),))], [LandmarkSpec("R", "red")]
        )


def _render_plain(
    world: SimWorld, cal: object, pose: tuple[float, float, float], backdrop: Backdrop | None = None
) -> np.ndarray:
    frame = render_panorama(
        pose, world, cal, np.random.default_rng(3), bearing_noise_rad=0.0,  # type: ignore[arg-type]
        vision_error_rad=0.05, backdrop=backdrop,
    )  # fmt: skip
    return frame.image_bgr


def test_a_wall_of_a_landmark_colour_is_rejected_as_too_wide() -> None:
    """Unwrapped 360 x 120: a red landmark 6 cm wide seen from 0.3..3 m spans 1.1..11.5 deg;
    a red wall all round is one blob 360 deg wide, rejected with the reason; the landmark
    alone, at 0.32 m (near r_min) and at 2.9 m (near r_max), passes."""
    from data_schemas.calibration import UnwrappedCalibration

    cal = UnwrappedCalibration(360, 120)
    catalog = [
        LandmarkSpec("R", "red", width_m=0.06, height_m=0.2),
        LandmarkSpec("G", "green", width_m=0.06),
    ]
    extractor = BearingExtractor(cal, catalog, range_m=(0.3, 3.0))
    for distance in (0.32, 2.9):
        world = SimWorld(
            Arena(4.0, 2.0),
            (
                Landmark("R", 0.1 + distance, 1.0, "red", radius_m=0.03),
                Landmark("G", 3.9, 1.9, "green", radius_m=0.03),
            ),
        )
        got = extractor.extract(_render_plain(world, cal, (0.1, 1.0, 0.0)))["R"]
        assert got.bearing_rad is not None and abs(got.bearing_rad) < 0.5 * DEG, distance
    red_wall = Backdrop(wall_bgr=(0.0, 0.0, 220.0))
    world = SimWorld(
        Arena(4.0, 2.0),
        (
            Landmark("R", 1.5, 1.0, "red", radius_m=0.03),
            Landmark("G", 3.9, 1.9, "green", radius_m=0.03),
        ),
    )
    image = _render_plain(world, cal, (0.1, 1.0, 0.0), red_wall)
    sightings = extractor.extract_classes(image)["red"]
    assert not sightings.blobs and len(sightings.rejected) == 1
    blob, why = sightings.rejected[0]
    assert math.degrees(blob.width_rad) > 300 and "wider than 0.06 m at 0.3 m (11.5 deg)" in why
    assert "no blob of a landmark's size" in extractor.extract(image)["R"].reason
    # without the catalog's range the wall is taken for the landmark
    assert BearingExtractor(cal, catalog).extract(image)["R"].bearing_rad is not None


def test_a_landmark_cut_by_the_image_edge_gives_no_bearing() -> None:
    """Pinhole: a landmark half outside the image would read at the bearing of its visible
    part; it is rejected as cut by the edge, and read when whole in view."""
    cal = simulated_pinhole(320, 240, 60 * DEG)
    world = SimWorld(
        Arena(4.0, 2.0),
        (Landmark("R", 1.1, 1.0, "red", radius_m=0.05), Landmark("G", 3.9, 1.9, "green")),
    )
    extractor = BearingExtractor(cal, [LandmarkSpec("R", "red"), LandmarkSpec("G", "green")])
    bearing = math.atan2(0.0, 1.0)
    for heading_deg, cut in ((0.0, False), (-30.0, True), (-25.0, False)):
        # R is 1 m ahead; half-width 2.9 deg; the image edge at 30 deg
        image = _render_plain(world, cal, (0.1, 1.0, math.radians(heading_deg)))
        got = extractor.extract(image)["R"]
        if cut:
            assert got.bearing_rad is None and "cut by the image's edge" in got.reason
        else:
            assert got.bearing_rad == pytest.approx(
                bearing - math.radians(heading_deg), abs=0.1 * DEG
            )


def test_greyscale_frames_are_refused_for_colour_landmarks() -> None:
    """A greyscale frame (one channel, or three equal ones as importers store it) cannot show
    colours: one line says so; a uniform black frame from a colour camera is not refused."""
    from data_schemas.calibration import UnwrappedCalibration

    image, _ = _plain_frame()
    extractor = BearingExtractor(UnwrappedCalibration(80, 60), [LandmarkSpec("R", "red")])
    grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    for frame in (grey, grey[..., None], cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)):
        with pytest.raises(ImageError, match="greyscale") as info:
            extractor.extract(frame)
        assert "\n" not in str(info.value) and "record colour frames" in str(info.value)
    black = np.zeros_like(image)
    assert extractor.extract(black)["R"].reason == "no pixels of its colour"
    assert extractor.extract(image)["R"].bearing_rad is not None
