"""Colour classes: defaults, hue wrap, overrides and catalog errors (real OpenCV HSV)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from data_schemas.calibration import UnwrappedCalibration
from data_schemas.colors import COLOR_NAMES, NOMINAL_BGR
from data_schemas.session import LandmarkSpec
from pipeline.bearings import DEFAULT_HSV, BearingExtractor, HsvBox, LandmarkCatalogError
from pipeline.bearings.classify import ColorClassifier


def _classes_of(bgr: tuple[int, int, int], boxes: list[HsvBox]) -> list[int]:
    """Indices of the boxes that claim one pixel of colour ``bgr``."""
    planes = ColorClassifier(boxes).classify(np.array([[bgr]], np.uint8))
    slots = ColorClassifier(boxes).slots
    return [k for k, s in enumerate(slots) if planes[s.plane][0, 0] & s.bit]


def test_every_catalog_colour_has_a_default_box() -> None:
    assert set(DEFAULT_HSV) == set(COLOR_NAMES)


@pytest.mark.parametrize("gain", [0.35, 0.7, 1.0, 1.15])
def test_nominal_colours_fall_in_their_own_class_only(gain: float) -> None:
    boxes = [DEFAULT_HSV[name] for name in COLOR_NAMES]
    for k, name in enumerate(COLOR_NAMES):
        bgr = tuple(min(255, round(c * gain)) for c in NOMINAL_BGR[name])
        assert _classes_of(bgr, boxes) == [k], (name, bgr)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    "bgr", [(128, 128, 128), (100, 108, 116), (250, 250, 250), (10, 10, 10), (163, 157, 150)]
)
def test_greys_and_background_are_in_no_class(bgr: tuple[int, int, int]) -> None:
    assert _classes_of(bgr, [DEFAULT_HSV[name] for name in COLOR_NAMES]) == []


def test_red_wraps_hue() -> None:
    red = DEFAULT_HSV["red"]
    assert red.wraps
    hsv = np.array([[[176, 200, 200], [3, 200, 200], [20, 200, 200]]], np.uint8)
    bgr = cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)
    got = [_classes_of(tuple(int(c) for c in px), [red]) for px in bgr[0]]  # type: ignore[arg-type]
    assert got == [[0], [0], []]


def test_more_than_eight_classes_use_several_planes() -> None:
    names = [*COLOR_NAMES, *COLOR_NAMES]  # 12 classes -> 2 planes
    clf = ColorClassifier([DEFAULT_HSV[n] for n in names])
    assert clf.n_planes == 2
    got = _classes_of(NOMINAL_BGR["cyan"], [DEFAULT_HSV[n] for n in names])
    assert got == [COLOR_NAMES.index("cyan"), 6 + COLOR_NAMES.index("cyan")]


def test_override_replaces_the_default_box() -> None:
    cal = UnwrappedCalibration(64, 16)
    image = np.full((16, 64, 3), 128, np.uint8)
    image[4:12, 20:26] = NOMINAL_BGR["green"]
    default = BearingExtractor(cal, [LandmarkSpec("g", "green")], min_pixels=4)
    assert default.extract(image)["g"].visible
    # an override that excludes pure green (hue 60) but takes a yellowish green
    narrow = LandmarkSpec("g", "green", hsv_lo=(35, 90, 50), hsv_hi=(50, 255, 255))
    assert not BearingExtractor(cal, [narrow], min_pixels=4).extract(image)["g"].visible
    image[4:12, 20:26] = (0, 200, 120)  # hue ~42
    assert BearingExtractor(cal, [narrow], min_pixels=4).extract(image)["g"].visible


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        (LandmarkSpec("L9", "purple"), "unknown colour 'purple'"),
        (LandmarkSpec("L9", "red", hsv_lo=(0, 0, 0)), "needs both 'lo' and 'hi'"),
        (LandmarkSpec("L9", "red", hsv_lo=(0, 0, 0), hsv_hi=(200, 255, 255)), "0..179"),
        (LandmarkSpec("L9", "red", hsv_lo=(0, 200, 0), hsv_hi=(10, 100, 255)), "S lower bound"),
    ],
)
def test_bad_catalog_entries_raise_one_clear_line(spec: LandmarkSpec, message: str) -> None:
    with pytest.raises(LandmarkCatalogError, match=message) as info:
        BearingExtractor(UnwrappedCalibration(32, 8), [spec])
    assert "\n" not in str(info.value) and "L9" in str(info.value)


def test_duplicate_landmark_names_are_refused() -> None:
    specs = [LandmarkSpec("A", "red"), LandmarkSpec("A", "blue")]
    with pytest.raises(LandmarkCatalogError, match="unique"):
        BearingExtractor(UnwrappedCalibration(32, 8), specs)
