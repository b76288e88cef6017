"""Angular profiles to blobs: circular runs, the seam, gaps, minimum size, components."""

from __future__ import annotations

import math

import numpy as np
import pytest

from data_schemas.calibration import UnwrappedCalibration
from pipeline.bearings.blobs import Profile, component_blobs, profile_blobs, profile_of_mask
from pipeline.bearings.layout import make_layout


def _profile(counts: list[int]) -> Profile:
    c = np.array(counts, np.int64)
    b = -math.pi + (np.arange(c.size) + 0.5) * (2 * math.pi / c.size)  # bin centres
    return Profile(c, c * np.cos(b), c * np.sin(b), 2 * math.pi / c.size)


def test_run_across_the_seam_is_one_blob_with_circular_mean() -> None:
    counts = [0] * 36
    counts[0], counts[1], counts[34], counts[35] = 5, 5, 5, 5  # straddles +-pi
    blobs, largest = profile_blobs(_profile(counts), min_pixels=1, max_gap_bins=0)
    assert len(blobs) == 1 and largest == 20
    assert abs(math.remainder(blobs[0].bearing_rad - math.pi, 2 * math.pi)) < 1e-9
    assert blobs[0].width_rad == pytest.approx(4 * 2 * math.pi / 36)


def test_two_runs_are_two_blobs_largest_first() -> None:
    counts = [0] * 36
    counts[5:8] = [4, 4, 4]
    counts[20:24] = [6, 6, 6, 6]
    blobs, largest = profile_blobs(_profile(counts), min_pixels=1, max_gap_bins=1)
    assert [b.n_pixels for b in blobs] == [24, 12] and largest == 24
    bin_rad = 2 * math.pi / 36
    assert blobs[0].bearing_rad == pytest.approx(-math.pi + 22 * bin_rad)
    assert blobs[1].bearing_rad == pytest.approx(-math.pi + 6.5 * bin_rad)
    assert [b.width_rad for b in blobs] == pytest.approx([4 * bin_rad, 3 * bin_rad])


@pytest.mark.parametrize(("gap", "n_blobs"), [(0, 2), (1, 2), (2, 1)])
def test_gap_bridging(gap: int, n_blobs: int) -> None:
    counts = [0] * 36
    counts[10:13] = [3, 3, 3]
    counts[15:18] = [3, 3, 3]  # two empty bins in between
    blobs, _ = profile_blobs(_profile(counts), min_pixels=1, max_gap_bins=gap)
    assert len(blobs) == n_blobs
    bin_rad = 2 * math.pi / 36
    assert sum(b.width_rad for b in blobs) == pytest.approx((6 if n_blobs == 2 else 8) * bin_rad)


def test_small_runs_are_not_blobs_but_their_size_is_reported() -> None:
    counts = [0] * 36
    counts[3] = 2
    counts[30] = 3
    assert profile_blobs(_profile(counts), min_pixels=4, max_gap_bins=1) == ([], 3)
    assert profile_blobs(_profile([0] * 36), min_pixels=4, max_gap_bins=1) == ([], 0)


def test_fully_occupied_profile_is_one_blob_all_round() -> None:
    blobs, _ = profile_blobs(_profile([2] * 36), min_pixels=1, max_gap_bins=1)
    assert len(blobs) == 1 and blobs[0].width_rad == pytest.approx(2 * math.pi)


def test_components_join_across_the_seam_and_split_stacked_blobs() -> None:
    cal = UnwrappedCalibration(40, 20)
    layout = make_layout(cal)
    mask = np.zeros((20, 40), np.uint8)
    mask[2:6, 0:2] = 1
    mask[2:6, 38:40] = 1  # same blob across column 0 / 39
    mask[12:18, 10:12] = 1
    mask[0:4, 10:12] = 1  # same columns, separate rows: two components
    blobs, largest = component_blobs(mask, layout, min_pixels=4)
    assert [b.n_pixels for b in blobs] == [16, 12, 8] and largest == 16
    seam = blobs[0]
    assert (
        abs(math.remainder(seam.bearing_rad - float(cal.bearing_of_column(0.0)), 2 * math.pi))
        < 1e-9
    )
    assert seam.width_rad == pytest.approx(4 * 2 * math.pi / 40)
    # the profile method sees the stacked pair as one run of columns
    prof_blobs, _ = profile_blobs(profile_of_mask(mask, 1, layout), min_pixels=4, max_gap_bins=1)
    assert [b.n_pixels for b in prof_blobs] == [20, 16]
