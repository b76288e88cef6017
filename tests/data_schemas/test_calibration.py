from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from data_schemas.angles import wrap_rad
from data_schemas.calibration import (
    OmniCalibration,
    UnwrappedCalibration,
    calibration_from_dict,
    default_omni,
)
from data_schemas.errors import CalibrationError

angles = st.floats(-50.0, 50.0, allow_nan=False)


@given(angles)
def test_wrap_range_and_equivalence(a: float) -> None:
    w = wrap_rad(a)
    assert -math.pi <= w < math.pi
    assert math.isclose(math.cos(w), math.cos(a), abs_tol=1e-9)
    assert math.isclose(math.sin(w), math.sin(a), abs_tol=1e-9)
    assert float(wrap_rad(np.array([a]))[0]) == pytest.approx(w, abs=1e-12)


def test_wrap_pi_goes_to_minus_pi() -> None:
    assert wrap_rad(math.pi) == -math.pi


def test_unwrapped_defaults_forward_at_centre() -> None:
    cal = UnwrappedCalibration(255, 176)
    assert float(cal.bearing_of_column(255 / 2)) == pytest.approx(0.0, abs=1e-12)
    # to the right of centre the bearing is negative (clockwise)
    assert float(cal.bearing_of_column(255 * 0.75)) == pytest.approx(-math.pi / 2)


@given(st.floats(-math.pi, math.pi - 1e-9), st.sampled_from([-1, 1]), angles)
def test_unwrapped_column_round_trip(b: float, direction: int, offset: float) -> None:
    cal = UnwrappedCalibration(640, 100, offset_rad=offset, direction=direction)
    u = cal.column_of_bearing(b)
    assert 0 <= u < 640
    assert math.cos(float(cal.bearing_of_column(u)) - b) == pytest.approx(1.0, abs=1e-9)


@given(st.floats(-math.pi, math.pi - 1e-9), st.sampled_from([-1, 1]))
def test_omni_pixel_round_trip(b: float, direction: int) -> None:
    cal = OmniCalibration(300, 300, 150, 150, 40, 140, direction=direction)
    x, y = cal.pixel_of_bearing(b, 90.0)
    assert math.hypot(float(x) - 150, float(y) - 150) == pytest.approx(90.0)
    assert math.cos(float(cal.bearing_of_pixel(x, y)) - b) == pytest.approx(1.0, abs=1e-9)


def test_omni_default_forward_is_up() -> None:
    cal = default_omni(200, 200)
    assert float(cal.bearing_of_pixel(100, 10)) == pytest.approx(0.0, abs=1e-12)
    assert float(cal.bearing_of_pixel(10, 100)) == pytest.approx(math.pi / 2)


def test_dict_round_trip() -> None:
    cals = (UnwrappedCalibration(255, 176, offset_rad=1.0, direction=1), default_omni(320, 240))
    for cal in cals:
        assert calibration_from_dict(cal.to_dict()) == cal


def test_dict_form_is_in_degrees() -> None:
    # a round trip hides a unit error made both ways: the JSON form against values by hand
    doc = UnwrappedCalibration(255, 176, offset_rad=math.pi / 4, direction=1).to_dict()
    assert doc["offset_deg"] == pytest.approx(45.0, abs=1e-12)
    doc = OmniCalibration(300, 300, 150, 150, 40, 140, offset_rad=-math.pi / 2).to_dict()
    assert doc["offset_deg"] == pytest.approx(-90.0, abs=1e-12)
    unwrapped = calibration_from_dict(
        {"model": "unwrapped", "width": 8, "height": 2, "offset_deg": 90}
    )
    assert isinstance(unwrapped, UnwrappedCalibration)
    assert unwrapped.offset_rad == pytest.approx(math.pi / 2, abs=1e-15)
    omni = calibration_from_dict(
        {"model": "omni", "width": 300, "height": 300, "r_min": 40, "r_max": 140, "offset_deg": 30}
    )
    assert isinstance(omni, OmniCalibration)
    assert omni.offset_rad == pytest.approx(math.pi / 6, abs=1e-15)


@pytest.mark.parametrize(
    ("doc", "message"),
    [
        ({"model": "fisheye", "width": 2, "height": 2}, "unknown camera model"),
        ({"model": "omni", "width": 10, "height": 10, "r_max": 3}, "missing key 'r_min'"),
        ({"model": "unwrapped", "width": 0, "height": 10}, "must be positive"),
        ({"model": "omni", "width": 9, "height": 9, "r_min": 5, "r_max": 2}, "r_min < r_max"),
    ],
)
def test_bad_calibration(doc: dict[str, object], message: str) -> None:
    with pytest.raises(CalibrationError, match=message):
        calibration_from_dict(doc)
