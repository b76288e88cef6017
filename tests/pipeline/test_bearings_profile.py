"""Angular profiles to blobs: circular runs, the seam, gaps, minimum size, components."""

from __future__ import annotations

import math

import numpy as np
import pytest

from data_schemas.calibration import OmniCalibration, UnwrappedCalibration
from pipeline.bearings.blobs import (
    Profile,
    component_blobs,
    profile_blobs,
    profile_of_mask,
    profiles_blobs,
    profiles_of_bits,
)
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


# ------------------------------------------------------- several classes at once
def _runs_by_hand(counts: list[int], gap: int) -> list[list[int]]:
    """Circular runs of occupied bins, each as its bins from its first one: walk the circle from
    just after the widest empty stretch, split where more than ``gap`` empty bins follow."""
    n = len(counts)
    occupied = [i for i in range(n) if counts[i]]
    if not occupied:
        return []
    # the bin after the longest empty stretch (the whole circle if every bin is occupied)
    empty_after = [(occupied[(k + 1) % len(occupied)] - b - 1) % n for k, b in enumerate(occupied)]
    if len(occupied) == n:
        empty_after = [0] * n
    k0 = (max(range(len(occupied)), key=lambda k: empty_after[k]) + 1) % len(occupied)
    order = occupied[k0:] + occupied[:k0]
    runs = [[order[0]]]
    for b in order[1:]:
        if (b - runs[-1][-1] - 1) % n > gap:
            runs.append([b])
        else:
            runs[-1].append(b)
    if len(runs) > 1 and (runs[0][0] - runs[-1][-1] - 1) % n <= gap:
        runs[0] = runs.pop() + runs[0]  # the walk began inside a run: it wraps around
    return runs


def _blobs_by_hand(
    counts: list[int], gap: int, min_pixels: int, bin_rad: float
) -> tuple[list[tuple[int, float, float]], int]:
    """(pixels, bearing, width) of each run with ``min_pixels`` or more, largest first (ties:
    in the order of the runs' first bins), and the largest run's pixels."""
    runs = _runs_by_hand(counts, gap)
    found = []
    for run in runs:
        px = sum(counts[b] for b in run)
        centre = [-math.pi + (b + 0.5) * bin_rad for b in run]
        east = sum(counts[b] * math.cos(c) for b, c in zip(run, centre, strict=True))
        north = sum(counts[b] * math.sin(c) for b, c in zip(run, centre, strict=True))
        first, last = run[0], run[-1]
        width = len(counts) if len(run) == len(counts) else (last - first) % len(counts) + 1
        found.append((px, math.atan2(north, east), width * bin_rad, first))
    largest = max((f[0] for f in found), default=0)
    kept = sorted((f for f in found if f[0] >= min_pixels), key=lambda f: (-f[0], f[3]))
    return [f[:3] for f in kept], largest


@pytest.mark.parametrize("seed", range(6))
def test_many_profiles_at_once_are_their_runs_by_hand(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 48
    bin_rad = 2 * math.pi / n
    rows = []
    for k in range(7):
        fill = [0.0, 0.05, 0.3, 0.6, 1.0, 0.15, 0.9][k]  # empty, sparse ... full
        row = np.where(rng.random(n) < fill, rng.integers(1, 6, n), 0)
        rows.append(row)
    rows[3][[0, 1, n - 1]] = [4, 4, 4]  # a run across the seam
    rows[5][:] = 0
    rows[5][17] = 9  # one bin
    counts = np.array(rows, np.int64)
    centre = -math.pi + (np.arange(n) + 0.5) * bin_rad
    profile = Profile(counts, counts * np.cos(centre), counts * np.sin(centre), bin_rad)
    for gap in (0, 1, 3):
        got = profiles_blobs(profile, min_pixels=5, max_gap_bins=gap)
        assert len(got) == len(rows)
        for row, (blobs, largest) in zip(rows, got, strict=True):
            want, want_largest = _blobs_by_hand(row.tolist(), gap, 5, bin_rad)
            assert largest == want_largest
            assert [b.n_pixels for b in blobs] == [w[0] for w in want]
            assert [b.width_rad for b in blobs] == pytest.approx([w[2] for w in want])
            for b, w in zip(blobs, want, strict=True):
                assert abs(math.remainder(b.bearing_rad - w[1], 2 * math.pi)) < 1e-12
                assert -math.pi <= b.bearing_rad < math.pi


def test_profiles_of_bits_count_each_class_pixel_by_pixel() -> None:
    """Unwrapped: column counts; omni: every ring pixel's sector, cos and sin added by hand."""
    rng = np.random.default_rng(3)
    slots = [(0, 1), (0, 4), (1, 2), (0, 128), (1, 1)]
    for cal in (UnwrappedCalibration(40, 20), OmniCalibration(60, 50, 30.0, 25.0, 8.0, 22.0)):
        layout = make_layout(cal)
        crop = (slice(None), slice(None)) if isinstance(cal, UnwrappedCalibration) else layout.crop
        shape = np.zeros((cal.height, cal.width))[crop].shape
        planes = [rng.integers(0, 256, shape).astype(np.uint8) for _ in range(2)]
        if not isinstance(cal, UnwrappedCalibration):
            planes = [np.where(layout.ring > 0, p, 0).astype(np.uint8) for p in planes]
        got = profiles_of_bits(planes, slots, layout)
        n = layout.n_bins
        for k, (p, bit) in enumerate(slots):
            counts = np.zeros(n, np.int64)
            cos = np.zeros(n)
            sin = np.zeros(n)
            for y, x in zip(*np.nonzero(planes[p] & bit), strict=True):
                if isinstance(cal, UnwrappedCalibration):
                    b, c, s = x, layout.bin_cos[x], layout.bin_sin[x]
                else:
                    b, c, s = layout.pixel_bin[y, x], layout.pixel_cos[y, x], layout.pixel_sin[y, x]
                counts[b] += 1
                cos[b] += c
                sin[b] += s
            assert np.array_equal(got.counts[k], counts)
            assert got.cos_sum[k] == pytest.approx(cos, abs=1e-12)
            assert got.sin_sum[k] == pytest.approx(sin, abs=1e-12)
    assert profiles_of_bits(planes, [], layout).counts.shape == (0, layout.n_bins)
