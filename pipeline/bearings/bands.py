"""Band codes: find coded landmarks by their sequence of colours along a column or a ray.

A coded landmark is a stack of two or more coloured bands of equal heights, listed top to
bottom. In an unwrapped panorama its bands are stacked in its columns, the top band in the upper
rows; in an omni image they follow each ray, the top band outermost (radius grows with
elevation). The band colours' class bits become a colour label per cell of a (rows, bins) grid,
rows from the highest elevation down and bins the layout's angular bins (omni: labels are
taken per ring row and sector, and a cell no pixel falls in takes the label of the nearest one
within ``gap_bins / 2`` sectors, so that the inner rows, where a pixel spans several sectors,
have no holes). Each bin's column of labels is
read as runs of one colour:

1. runs of one colour separated by a short gap (at most 2 rows or the shorter run) are joined:
   something thin in front of a band;
2. the runs split into stacks at longer gaps;
3. slivers (at most :data:`BLEND_ROWS` rows) whose hue lies between the hues of the runs above
   and below are dropped: where two bands meet, anti-aliased pixels blend their colours
   (magenta over yellow looks red, yellow over cyan green), which would read as a band;
4. a stack that is a code, or holds one as a contiguous part, reads the code in full in that
   bin (longest codes first, without overlap);
5. a stack that is a contiguous part of a code (one band hidden there) reads it partially.

The bins where a code was read in full anchor its blobs; adjacent bins where it was read partly
extend them (a band hidden in some columns). A blob's bearing is the circular mean over the
code's pixels in its bins (seam-safe, :func:`pipeline.bearings.blobs.profile_blobs`). A band
partly hidden (shorter) does not stop the code being read; the band heights are not otherwise
checked, since perspective and a partial view both change them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import TWO_PI, wrap_rad
from pipeline.bearings.blobs import Blob
from pipeline.bearings.layout import Layout, OmniLayout, PinholeLayout, PixelLayout

Run = tuple[int, int, int]  # colour label (1..), first row, row past the last

#: Thickest run (rows) that may be a blend of the bands above and below it.
BLEND_ROWS = 2


@dataclass(frozen=True)
class BandGrid:
    """Colour labels on the (rows, bins) grid of one frame, kept for the bins that hold any.

    Attributes
    ----------
    bins : ndarray, (m,) intp
        The angular bins holding band colours, increasing.
    labels : ndarray, (n_rows, m) uint8
        0 = no band colour, ``k + 1`` = band colour ``k``; row 0 is the highest elevation.
    pixels : ndarray, (n_rows + 1, m) int64
        Cumulative count (down the rows) of labelled pixels per bin, first row 0: the pixels
        of rows ``a..b-1`` in ``bins[i]`` are ``pixels[b, i] - pixels[a, i]``.
    """

    bins: NDArray[np.intp]
    labels: NDArray[np.uint8]
    pixels: NDArray[np.int64]


class BandDecoder:
    """Read band codes in frames of one calibration.

    Parameters
    ----------
    layout : Layout
        The extractor's angular bins (columns or ring sectors).
    hues : sequence of float
        Nominal hue (OpenCV units, 0..180) of each band colour (labels 1..len(hues)).
    codes : sequence of tuple of int
        Each code's band colours (0-based colour indices), top to bottom, two or more.
    min_pixels, max_gap_bins : int
        As for single-colour blobs.
    """

    def __init__(
        self,
        layout: Layout,
        hues: Sequence[float],
        codes: Sequence[tuple[int, ...]],
        *,
        min_pixels: int,
        max_gap_bins: int,
    ) -> None:
        self.layout = layout
        self.n_colors = len(hues)
        self._hues = [0.0, *hues]  # by label
        self.codes = [tuple(c + 1 for c in code) for code in codes]  # as labels
        self.min_pixels = min_pixels
        self.max_gap_bins = max_gap_bins
        self._full = {code: k for k, code in enumerate(self.codes)}
        self._lengths = sorted({len(code) for code in self.codes})
        self._parts: dict[tuple[int, ...], list[int]] = {}
        for k, code in enumerate(self.codes):
            parts = {code[a:b] for a in range(len(code)) for b in range(a + 1, len(code) + 1)}
            for part in parts - {code}:
                self._parts.setdefault(part, []).append(k)
        # between[h, a, b]: label h's hue lies between labels a's and b's (a blend of the two)
        n_labels = self.n_colors + 1
        self._between = np.zeros((n_labels, n_labels, n_labels), np.bool_)
        for h, a, b in np.ndindex(self._between.shape):
            if 0 not in (h, a, b) and len({h, a, b}) == 3:
                self._between[h, a, b] = _hue_between(self._hues[h], self._hues[a], self._hues[b])
        n = layout.n_bins
        if isinstance(layout, PixelLayout):
            centre = -math.pi + (np.arange(n) + 0.5) * (TWO_PI / n)
            self._cos, self._sin = np.cos(centre), np.sin(centre)
            self._omni = _OmniRows(layout)
        else:
            self._cos, self._sin = layout.bin_cos, layout.bin_sin

    def grid(self, labels_region: NDArray[np.uint8]) -> BandGrid:
        """The (rows, bins) grid of a frame's band-colour labels (region-sized, 0 = none).

        A cell whose hue lies between those of its two angular neighbours is cleared: where two
        landmarks meet side by side, a column blends their colours (magenta beside cyan looks
        blue), which could read as another code.
        """
        if isinstance(self.layout, PixelLayout):
            bins, labels, counts = self._omni.grid(labels_region)
        else:
            bins = np.flatnonzero(labels_region.any(axis=0))
            labels = labels_region[:, bins]
            counts = (labels > 0).astype(np.int64)
        n = self.layout.n_bins
        m = bins.size
        if m:
            left, right = _neighbour(bins, -1, n), _neighbour(bins, 1, n)
            zero = np.zeros((labels.shape[0], 1), np.uint8)
            padded = np.hstack([labels, zero])  # column m: no neighbour
            side = self._between[labels, padded[:, left], padded[:, right]]
            if side.any():
                labels = np.where(side, 0, labels).astype(np.uint8)
        pixels = np.zeros((labels.shape[0] + 1, m), np.int64)
        np.cumsum(counts, axis=0, out=pixels[1:])
        return BandGrid(bins, labels, pixels)

    def decode(self, grid: BandGrid) -> list[tuple[list[Blob], int]]:
        """Per code (in order): its blobs (largest first) and the largest run's pixel count
        (0 where the code was nowhere read in full)."""
        n_codes, n_bins = len(self.codes), self.layout.n_bins
        full = np.zeros((n_codes, n_bins), np.int64)
        part = np.zeros((n_codes, n_bins), np.int64)
        for i, runs in _column_runs(grid.labels):
            for stack in _stacks(runs):
                self._read(stack, i, int(grid.bins[i]), grid.pixels, full, part)
        return self._blobs(full, part)

    def _blobs(
        self, full: NDArray[np.int64], part: NDArray[np.int64]
    ) -> list[tuple[list[Blob], int]]:
        """Per code, its blobs: circular runs of bins read in full or partly (gaps of at most
        ``max_gap_bins`` bridged) holding a bin read in full, with at least ``min_pixels``
        pixels, largest first; and the largest anchored run's pixel count.

        All codes at once: runs are found on the sorted (code, bin) pairs of the occupied bins.
        """
        n_codes, n = full.shape
        out: list[tuple[list[Blob], int]] = [([], 0) for _ in range(n_codes)]
        counts = full + part
        code, bins = np.nonzero(counts)  # sorted by code, then bin
        if code.size == 0:
            return out
        px = counts[code, bins]
        new_code = np.r_[True, code[1:] != code[:-1]]
        gap = np.r_[0, np.diff(bins) - 1]
        start = new_code | (gap > self.max_gap_bins)
        run = np.cumsum(start) - 1
        n_runs = int(run[-1]) + 1
        first_bin = bins[start]  # runs in array order: first and last bin of each
        last_bin = bins[np.r_[np.flatnonzero(start)[1:], code.size] - 1]
        # across the seam: a code's last run joins its first if the gap through bin 0 is short
        firsts = np.flatnonzero(new_code)
        lasts = np.r_[firsts[1:], code.size] - 1
        wrap = (bins[firsts] + n - bins[lasts] - 1 <= self.max_gap_bins) & (
            run[firsts] != run[lasts]
        )
        for f, z in zip(firsts[wrap].tolist(), lasts[wrap].tolist(), strict=True):
            head, tail = run[f], run[z]
            first_bin[head] = first_bin[tail]  # the joined run starts before the seam
            run[run == tail] = head
        n_px = np.bincount(run, weights=px, minlength=n_runs)
        anchored = np.bincount(run, weights=full[code, bins] > 0, minlength=n_runs) > 0
        cos_s = np.bincount(run, weights=px * self._cos[bins], minlength=n_runs)
        sin_s = np.bincount(run, weights=px * self._sin[bins], minlength=n_runs)
        run_code = np.zeros(n_runs, np.intp)
        run_code[run] = code
        width = ((last_bin - first_bin) % n + 1) * self.layout.bin_width_rad
        keep = anchored & (n_px >= self.min_pixels)
        largest = np.zeros(n_codes)
        np.maximum.at(largest, run_code[anchored], n_px[anchored])
        order = np.lexsort((-n_px, run_code))
        for r in order[keep[order]].tolist():
            out[int(run_code[r])][0].append(
                Blob(
                    int(n_px[r]),
                    wrap_rad(math.atan2(float(sin_s[r]), float(cos_s[r]))),
                    float(width[r]),
                )
            )
        return [(blobs, int(largest[k])) for k, (blobs, _) in enumerate(out)]

    def _read(
        self,
        stack: list[Run],
        i: int,
        j: int,
        pixels: NDArray[np.int64],
        full: NDArray[np.int64],
        part: NDArray[np.int64],
    ) -> None:
        """Record in bin ``j`` (grid column ``i``) the codes one stack reads in full, or else
        partly."""
        stack = _without_blends(stack, self._hues)
        found = self._full_matches(stack)
        for k, top, bottom in found:
            full[k, j] += pixels[bottom, i] - pixels[top, i]
        if found:
            return
        key = tuple(c for c, _, _ in stack)
        for k in self._parts.get(key, ()):
            part[k, j] += pixels[stack[-1][2], i] - pixels[stack[0][1], i]

    def _full_matches(self, stack: list[Run]) -> list[tuple[int, int, int]]:
        """Codes held in ``stack`` as contiguous runs, longest first and not overlapping:
        (code, first row, row past the last)."""
        colors = tuple(c for c, _, _ in stack)
        used = [False] * len(colors)
        found = []
        for n in reversed(self._lengths):
            for a in range(len(colors) - n + 1):
                k = self._full.get(colors[a : a + n])
                if k is not None and not any(used[a : a + n]):
                    used[a : a + n] = [True] * n
                    found.append((k, stack[a][1], stack[a + n - 1][2]))
        return found


def _neighbour(bins: NDArray[np.intp], step: int, n_bins: int) -> NDArray[np.intp]:
    """Position in ``bins`` of each bin's neighbour ``step`` away (circular), or ``bins.size``."""
    target = (bins + step) % n_bins
    pos = np.searchsorted(bins, target) % bins.size
    return np.where(bins[pos] == target, pos, bins.size)


def _column_runs(labels: NDArray[np.uint8]) -> list[tuple[int, list[Run]]]:
    """Per grid column with any label: its runs of one label down the rows (label, start, stop)."""
    cols = np.flatnonzero(labels.any(axis=0))
    if cols.size == 0:
        return []
    n_rows = labels.shape[0]
    padded = np.zeros((cols.size, n_rows + 2), np.int16)
    padded[:, 1:-1] = labels[:, cols].T
    flat = padded.ravel()
    edges = np.flatnonzero(flat[1:] != flat[:-1]) + 1  # first index of each new value
    starts, stops = edges[:-1], edges[1:]
    values = flat[starts]
    keep = values != 0  # padding keeps runs inside one column
    starts, stops, values = starts[keep], stops[keep], values[keep]
    width = n_rows + 2
    col_of = starts // width
    first = (starts - col_of * width - 1).tolist()
    last = (stops - col_of * width - 1).tolist()
    out: list[tuple[int, list[Run]]] = []
    current = -1
    for c, v, a, b in zip(col_of.tolist(), values.tolist(), first, last, strict=True):
        if c != current:
            out.append((int(cols[c]), []))
            current = c
        out[-1][1].append((v, a, b))
    return out


def _stacks(runs: list[Run]) -> list[list[Run]]:
    """Join one colour's runs across short gaps, then split the column into touching stacks."""
    joined: list[Run] = []
    for run in runs:
        if joined:
            c, a, b = joined[-1]
            gap = run[1] - b
            if run[0] == c and gap <= max(2, min(b - a, run[2] - run[1])):
                joined[-1] = (c, a, run[2])
                continue
        joined.append(run)
    stacks: list[list[Run]] = []
    for run in joined:
        if stacks:
            prev = stacks[-1][-1]
            if run[1] - prev[2] <= 2:
                stacks[-1].append(run)
                continue
        stacks.append([run])
    return stacks


def _without_blends(stack: list[Run], hues: Sequence[float]) -> list[Run]:
    """``stack`` without slivers whose hue lies between their neighbours' (a blend of the two
    bands), runs of one colour rejoined."""
    if len(stack) < 3:
        return stack
    kept = [stack[0]]
    for i in range(1, len(stack) - 1):
        run = stack[i]
        if not (
            run[2] - run[1] <= BLEND_ROWS
            and _hue_between(hues[run[0]], hues[stack[i - 1][0]], hues[stack[i + 1][0]])
        ):
            kept.append(run)
    kept.append(stack[-1])
    out: list[Run] = []
    for run in kept:
        if out and out[-1][0] == run[0]:
            out[-1] = (run[0], out[-1][1], run[2])
        else:
            out.append(run)
    return out


def _hue_between(h: float, a: float, b: float) -> bool:
    """True if hue ``h`` lies strictly inside the shorter arc from ``a`` to ``b`` (0..180);
    for complementary ``a`` and ``b`` (both arcs equal) inside either arc."""
    ab = (b - a + 90.0) % 180.0 - 90.0
    ah = (h - a + 90.0) % 180.0 - 90.0
    if abs(abs(ab) - 90.0) < 1e-9:
        return 0.0 < abs(ah) < 90.0
    return ab * ah > 0 and abs(ah) < abs(ab)


class _OmniRows:
    """Pixels of a per-pixel layout as (row, sector) cells, row 0 the highest elevation (omni:
    rings one pixel wide from ``r_max`` in; pinhole: image rows)."""

    def __init__(self, layout: OmniLayout | PinholeLayout) -> None:
        inside = np.flatnonzero(layout.ring.ravel())
        self.n_rows = layout.n_rows
        self.n_bins = layout.n_bins
        self.pixel = inside
        self.row = np.asarray(layout.pixel_row).ravel()[inside].astype(np.intp)
        self.bin = layout.pixel_bin.ravel()[inside].astype(np.intp)
        self.pool = layout.gap_bins // 2  # holes filled from this many sectors on each side

    def grid(
        self, labels_region: NDArray[np.uint8]
    ) -> tuple[NDArray[np.intp], NDArray[np.uint8], NDArray[np.int64]]:
        """Occupied sectors (with ``pool`` neighbours each side), their labels (rows, m) and pixel
        counts (rows, m). A cell no ring pixel falls in takes the label of the nearest labelled
        cell of its row within ``pool`` sectors (nearer the centre a pixel spans several)."""
        label = labels_region.ravel()[self.pixel]
        hit = np.flatnonzero(label)
        n, p = self.n_bins, self.pool
        occupied = np.unique(self.bin[hit])
        spread = (occupied[None, :] + np.arange(-p, p + 1)[:, None]) % n
        bins = np.unique(spread)
        m = bins.size
        index = self.row[hit] * m + np.searchsorted(bins, self.bin[hit])
        raw = np.bincount(index, minlength=self.n_rows * m).reshape(self.n_rows, m)
        labels = np.zeros(self.n_rows * m + 1, np.uint8)  # last entry: "no neighbour"
        labels[index] = label[hit]
        grid = labels[:-1].reshape(self.n_rows, m)
        if m:
            rows = np.arange(self.n_rows)[:, None] * m
            found = labels.copy()  # fill from pixels' own cells only
            for shift in range(1, p + 1):
                for step in (shift, -shift):
                    nb = _neighbour(bins, step, n)
                    source = np.where(nb < m, rows + nb[None, :], labels.size - 1)
                    holes = grid == 0
                    grid[holes] = found[source][holes]
        return bins, grid, raw
