"""Blobs of one colour class: from an angular profile (bin sums) or from connected components.

A blob's bearing is the circular mean of its pixels' bearings, ``atan2(sum sin, sum cos)``, so
a blob that straddles the +-pi seam (or column 0 / W-1) averages correctly. Its width is the
angular extent of the bins it occupies.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad
from pipeline.bearings.layout import Layout, PixelLayout, UnwrappedLayout


@dataclass(frozen=True)
class Blob:
    """One blob: pixel count, circular-mean bearing (rad, [-pi, pi)), angular width (rad)."""

    n_pixels: int
    bearing_rad: float
    width_rad: float


@dataclass(frozen=True)
class Profile:
    """Angular profile of a mask: per bin (n_bins,) pixel count and sums of cos/sin bearing.

    The profiles of several masks at once have (K, n_bins) arrays, one row per mask.
    """

    counts: NDArray[np.int64]
    cos_sum: NDArray[np.float64]
    sin_sum: NDArray[np.float64]
    bin_width_rad: float


def profile_of_mask(mask: NDArray[np.uint8], value: int, layout: Layout) -> Profile:
    """Angular profile of ``mask`` (crop-sized for omni; pixels are 0 or ``value``).

    Unwrapped: column sums. Omni, pinhole: the nonzero pixels' sectors from the precomputed
    table.
    """
    if isinstance(layout, UnwrappedLayout):
        sums = cv2.reduce(mask, 0, cv2.REDUCE_SUM, dtype=cv2.CV_32S)
        counts = sums[0].astype(np.int64) // value
        cos_sum, sin_sum = counts * layout.bin_cos, counts * layout.bin_sin
        return Profile(counts, cos_sum, sin_sum, layout.bin_width_rad)
    points = cv2.findNonZero(mask)
    if points is None:
        zeros = np.zeros(layout.n_bins)
        return Profile(np.zeros(layout.n_bins, np.int64), zeros, zeros, layout.bin_width_rad)
    xy = np.asarray(points, np.intp).reshape(-1, 2)
    return _omni_profile(layout, xy[:, 1], xy[:, 0])


def profiles_of_bits(
    planes: Sequence[NDArray[np.uint8]], slots: Sequence[tuple[int, int]], layout: Layout
) -> Profile:
    """Angular profiles of several classes at once: row ``k`` is the profile of the pixels of
    ``planes[p]`` (crop-sized for omni) with bit ``b`` set, ``(p, b) = slots[k]``.

    The same counts and sums, to the bit, as :func:`profile_of_mask` of each class's mask
    (each bin's pixels are summed in the same, row-major order).
    """
    n = layout.n_bins
    if isinstance(layout, UnwrappedLayout):
        counts = np.empty((len(slots), n), np.int64)
        for k, (p, bit) in enumerate(slots):
            mask = np.bitwise_and(planes[p], np.uint8(bit))
            counts[k] = cv2.reduce(mask, 0, cv2.REDUCE_SUM, dtype=cv2.CV_32S)[0] // bit
        return Profile(
            counts, counts * layout.bin_cos, counts * layout.bin_sin, layout.bin_width_rad
        )
    cells: list[NDArray[np.intp]] = []
    cos_w: list[NDArray[np.float64]] = []
    sin_w: list[NDArray[np.float64]] = []
    for p in sorted({p for p, _ in slots}):
        ys, xs = np.nonzero(planes[p])  # row-major, as cv2.findNonZero
        values = planes[p][ys, xs]
        bins = layout.pixel_bin[ys, xs].astype(np.intp)
        cos, sin = layout.pixel_cos[ys, xs], layout.pixel_sin[ys, xs]
        for k, (q, bit) in enumerate(slots):
            if q == p:
                on = (values & bit) != 0
                cells.append(bins[on] + k * n)
                cos_w.append(cos[on])
                sin_w.append(sin[on])
    size = len(slots) * n
    cell = np.concatenate(cells) if cells else np.zeros(0, np.intp)
    return Profile(
        np.bincount(cell, minlength=size).astype(np.int64).reshape(-1, n),
        np.asarray(np.bincount(cell, np.concatenate([*cos_w, []]), size), np.float64).reshape(
            -1, n
        ),
        np.asarray(np.bincount(cell, np.concatenate([*sin_w, []]), size), np.float64).reshape(
            -1, n
        ),
        layout.bin_width_rad,
    )


def _omni_profile(layout: PixelLayout, ys: NDArray[np.intp], xs: NDArray[np.intp]) -> Profile:
    """Angular profile of the ring pixels at rows ``ys``, columns ``xs`` (crop coordinates)."""
    bins = layout.pixel_bin[ys, xs]
    n = layout.n_bins
    cos_sum = np.bincount(bins, weights=layout.pixel_cos[ys, xs], minlength=n)
    sin_sum = np.bincount(bins, weights=layout.pixel_sin[ys, xs], minlength=n)
    return Profile(
        np.bincount(bins, minlength=n).astype(np.int64),
        np.asarray(cos_sum, np.float64),
        np.asarray(sin_sum, np.float64),
        layout.bin_width_rad,
    )


def profile_blobs(
    profile: Profile, *, min_pixels: int, max_gap_bins: int
) -> tuple[list[Blob], int]:
    """Split a profile into blobs: circular runs of occupied bins.

    Parameters
    ----------
    profile : Profile
        Angular profile of one class mask, (n_bins,) arrays.
    min_pixels : int
        Runs with fewer pixels are not blobs (noise, or a landmark too small to trust).
    max_gap_bins : int
        Runs separated by at most this many empty bins are one blob (bridges noise dropouts).

    Returns
    -------
    blobs : list of Blob
        Runs with at least ``min_pixels`` pixels, largest first.
    largest : int
        Pixel count of the largest run (0 if the mask is empty).
    """
    rows = Profile(
        profile.counts[None], profile.cos_sum[None], profile.sin_sum[None], profile.bin_width_rad
    )
    return profiles_blobs(rows, min_pixels=min_pixels, max_gap_bins=max_gap_bins)[0]


def profiles_blobs(
    profile: Profile, *, min_pixels: int, max_gap_bins: int
) -> list[tuple[list[Blob], int]]:
    """:func:`profile_blobs` of each row of (K, n_bins) profiles, all rows in one pass.

    A run ends at an occupied bin whose next occupied bin (circularly, in the same row) is more
    than ``max_gap_bins + 1`` bins on; the run holding a row's first bins without starting
    there wraps across the seam and is numbered last. A row with no such gap is one run whose
    extent is the circle less its widest gap. Ties in size keep the runs' order.

    Returns
    -------
    list of (list of Blob, int)
        Per row: its blobs, largest first, and the pixel count of its largest run (0 if empty).
    """
    counts = profile.counts
    n_rows, n_bins = counts.shape
    out: list[tuple[list[Blob], int]] = [([], 0) for _ in range(n_rows)]
    row, occupied = np.nonzero(counts)  # by row, then bin
    if row.size == 0:
        return out
    m = row.size
    new_row = np.empty(m, np.bool_)
    new_row[0] = True
    np.not_equal(row[1:], row[:-1], out=new_row[1:])
    first = np.flatnonzero(new_row)  # each row's first occupied bin
    last = np.concatenate((first[1:], [m])) - 1
    segment = np.cumsum(new_row, dtype=np.intp) - 1
    step = np.empty(m, np.intp)  # to the next occupied bin of the row, circular
    np.subtract(occupied[1:], occupied[:-1], out=step[:-1])
    step[last] = occupied[first] + n_bins - occupied[last]
    ends = step > max_gap_bins + 1  # the last bin of a run
    starts = np.empty(m, np.bool_)
    starts[1:] = ends[:-1]
    starts[first] = ends[last]
    one_run = np.add.reduceat(ends, first) == 0  # no gap wide enough in the row
    starts[first[one_run]] = True
    opened = np.cumsum(starts, dtype=np.intp)  # runs started so far
    run = opened - 1
    before = opened[first] - starts[first]  # runs of the rows before, = the row's first run
    wraps = opened == before[segment]  # bins before the row's first start: its last run
    run[wraps] = (opened[last] - 1)[segment[wraps]]
    n_runs = int(opened[-1])
    n_px = np.bincount(run, weights=counts[row, occupied], minlength=n_runs)
    first_bin = np.zeros(n_runs, np.intp)
    first_bin[run[starts]] = occupied[starts]
    last_bin = np.zeros(n_runs, np.intp)
    last_bin[run[ends]] = occupied[ends]
    width = (last_bin - first_bin) % n_bins + 1
    widest_gap = np.maximum.reduceat(step, first)
    width[before[one_run]] = n_bins - widest_gap[one_run] + 1
    run_row = np.empty(n_runs, np.intp)
    run_row[run] = row
    largest = np.maximum.reduceat(n_px, before)
    for r, size in zip(row[first].tolist(), largest.tolist(), strict=True):
        out[r] = ([], int(size))
    keep = np.flatnonzero(n_px >= min_pixels)
    if keep.size == 0:
        return out
    cos_s = np.bincount(run, weights=profile.cos_sum[row, occupied], minlength=n_runs)
    sin_s = np.bincount(run, weights=profile.sin_sum[row, occupied], minlength=n_runs)
    for r in keep[np.lexsort((keep, -n_px[keep], run_row[keep]))].tolist():
        out[int(run_row[r])][0].append(
            Blob(
                int(n_px[r]),
                wrap_rad(math.atan2(float(sin_s[r]), float(cos_s[r]))),
                int(width[r]) * profile.bin_width_rad,
            )
        )
    return out


def is_fringe(
    blob: Blob, others: list[Blob], *, max_width_rad: float, bin_width_rad: float
) -> bool:
    """True if ``blob`` looks like a mixed-colour fringe of one of ``others`` (other classes).

    Where two landmarks of different colours meet (one partly behind the other), anti-aliased
    pixels mix their colours (red + green looks yellow): a sliver at most ``max_width_rad``
    wide that shares bins with a blob of another class with at least as many pixels. Such a
    sliver is not a landmark. Merely adjacent blobs are kept (a thin landmark may stand beside
    another), but a partly hidden landmark whose visible part is such a sliver is dropped.
    """
    if blob.width_rad > max_width_rad * (1.0 + 1e-9):
        return False
    for other in others:
        reach = 0.5 * (blob.width_rad + other.width_rad) - 0.5 * bin_width_rad
        gap = abs(wrap_rad(blob.bearing_rad - other.bearing_rad))
        if other.n_pixels >= blob.n_pixels and gap <= reach:
            return True
    return False


def is_squeezed(
    blob: Blob,
    others: list[Blob],
    *,
    max_width_rad: float,
    bin_width_rad: float,
    kin: list[bool] | None = None,
) -> bool:
    """True if ``blob``, at most ``max_width_rad`` wide, touches blobs of ``others`` on both
    sides, or touches a larger one flagged in ``kin`` (parallel to ``others``).

    A column where two landmarks meet holds the top of one above the bottom of the other (the
    nearer one is taller), or blends of their colours: read as a band code it is a landmark
    that is not there. ``kin`` marks the neighbours such a phantom could be made of (for codes:
    those whose top or bottom band is the blob's). A far code that narrow in such company is
    dropped with it: then it is not visible, never a wrong bearing.
    """
    if blob.width_rad > max_width_rad * (1.0 + 1e-9):
        return False
    left = right = False
    for k, other in enumerate(others):
        offset = wrap_rad(other.bearing_rad - blob.bearing_rad)
        if abs(offset) <= 0.5 * (blob.width_rad + other.width_rad) + 0.75 * bin_width_rad:
            if kin is not None and kin[k] and other.n_pixels > blob.n_pixels:
                return True
            left |= offset < 0
            right |= offset > 0
    return left and right


def is_covered(blob: Blob, others: list[Blob], *, fraction: float = 0.5) -> bool:
    """True if one of ``others`` spans at least ``fraction`` of ``blob``'s angular extent.

    Two band codes read over the same bearings cannot both be landmarks there (a nearer one
    hides the farther one): where they overlap that much, the columns mix parts of both.
    """
    for other in others:
        offset = abs(wrap_rad(other.bearing_rad - blob.bearing_rad))
        shared = min(0.5 * blob.width_rad, offset + 0.5 * other.width_rad) - max(
            -0.5 * blob.width_rad, offset - 0.5 * other.width_rad
        )
        if shared >= fraction * blob.width_rad:
            return True
    return False


def component_blobs(
    mask: NDArray[np.uint8], layout: Layout, *, min_pixels: int
) -> tuple[list[Blob], int]:
    """Blobs as 8-connected components of ``mask`` (the slower reference method).

    Unwrapped panoramas join components that touch across the column 0 / W-1 seam.

    Returns
    -------
    blobs : list of Blob
        Components with at least ``min_pixels`` pixels, largest first.
    largest : int
        Pixel count of the largest component (0 if the mask is empty).
    """
    n_labels, labels_mat, stats_mat, _ = cv2.connectedComponentsWithStats(
        mask, connectivity=8, ltype=cv2.CV_32S
    )
    labels, stats = np.asarray(labels_mat, np.int32), np.asarray(stats_mat, np.int32)
    if n_labels == 1:
        return [], 0
    root = np.arange(n_labels)
    if isinstance(layout, UnwrappedLayout):
        _join_seam(labels, root)
    area = np.bincount(root[1:], weights=stats[1:, cv2.CC_STAT_AREA], minlength=n_labels)
    blobs = []
    for r in np.argsort(-area, kind="stable"):
        if area[r] < min_pixels:
            break
        profile = _component_profile(labels, stats, np.flatnonzero(root == r), layout)
        blobs.append(profile_blobs(profile, min_pixels=0, max_gap_bins=layout.n_bins)[0][0])
    return blobs, int(area.max())


def _join_seam(labels: NDArray[np.int32], root: NDArray[np.intp]) -> None:
    """Union (in ``root``) components touching across the left/right image edge (8-connected)."""
    left, right = labels[:, 0], labels[:, -1]
    h = labels.shape[0]
    for shift in (-1, 0, 1):
        a = left[max(0, -shift) : h - max(0, shift)]
        b = right[max(0, shift) : h - max(0, -shift)]
        both = (a > 0) & (b > 0)
        for la, lb in set(zip(a[both].tolist(), b[both].tolist(), strict=True)):
            ra, rb = _find(root, la), _find(root, lb)
            root[max(ra, rb)] = min(ra, rb)
    for label in range(root.size):
        root[label] = _find(root, label)


def _find(root: NDArray[np.intp], label: int) -> int:
    while root[label] != label:
        label = int(root[label])
    return label


def _component_profile(
    labels: NDArray[np.int32], stats: NDArray[np.int32], members: NDArray[np.intp], layout: Layout
) -> Profile:
    """Angular profile of the union of components ``members`` (each cut out by its bbox)."""
    counts = np.zeros(layout.n_bins, np.int64)
    cos_sum = np.zeros(layout.n_bins)
    sin_sum = np.zeros(layout.n_bins)
    for k in members:
        x, y, w, h = (int(v) for v in stats[k, :4])
        sub = labels[y : y + h, x : x + w] == k
        if isinstance(layout, UnwrappedLayout):
            col = sub.sum(axis=0)
            counts[x : x + w] += col
            cos_sum[x : x + w] += col * layout.bin_cos[x : x + w]
            sin_sum[x : x + w] += col * layout.bin_sin[x : x + w]
        else:
            ys, xs = np.nonzero(sub)
            part = _omni_profile(layout, ys + y, xs + x)
            counts += part.counts
            cos_sum += part.cos_sum
            sin_sum += part.sin_sum
    return Profile(counts, cos_sum, sin_sum, layout.bin_width_rad)
