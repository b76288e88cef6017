"""Learn the HSV boxes of a catalog's colours from a few frames where the user marked each
landmark (``bslam calibrate colors``).

A mark names a landmark in a frame by *points* on it (a few pixels per band are enough) or by
the *columns* it occupies. From the marks come, per colour name, the landmark pixels of that
colour (positives), and from the rest of the marked frames the pixels that no landmark covers
(negatives: floor, walls, posters, the room):

* a point gives the 3 x 3 pixels around it, given to the landmark's colour (the band) whose
  nominal hue is nearest theirs;
* columns give, row by row, the pixels of the strip's middle half that differ in colour from
  the strip's surroundings on both sides (a floor or a wall runs on past the landmark; the
  landmark does not); each such row goes to the band colour nearest its hue, except rows within
  2 of another colour (two bands, or the landmark and what is behind it, blend there).

The landmark's region, cut out of the negatives, is what a flood fill of similar colour reaches
from the points (or from the middle of each colour's rows): the blended pixels at its edges stay
negatives, so that a box does not take a blend of a landmark and its background (blue before a
pink wall looks magenta) for its colour.

Each colour's box is centred on its positives' circular-mean hue, and the most tolerant box is
kept, of a grid from the widest (hue spread + 8 units, saturation and value floors well below
the darkest positives, for light dimmer than in the marked frames) to the tightest (value
floor first: brightness changes most between frames; then hue; then saturation), that holds
98 % of the positives and at most :data:`NEGATIVE_SHARE` of the negatives and of the other
colours' positives. Every landmark of a colour, and every band of that colour, gets its box.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import cv2
import numpy as np
from numpy.typing import NDArray

from data_schemas.errors import ImageError
from data_schemas.session import LandmarkSpec
from pipeline.bearings.color_classes import DEFAULT_HSV, HsvBox, LandmarkCatalogError

#: A box may take at most this share of the negatives (pixels of no landmark) ...
NEGATIVE_SHARE = 1e-4
#: ... and must hold at least this share of its positives.
POSITIVE_SHARE = 0.98
#: Marked regions are cut out of the negatives with this margin, pixels (anti-aliased edges).
REGION_MARGIN_PX = 0
_HUE_MARGINS = (8, 6, 4, 2, 0)
_S_FACTORS = (0.6, 0.75, 0.9, 1.0)
_V_FACTORS = (0.4, 0.6, 0.8, 1.0)
_FLOOD_TOLERANCE = 24  # per BGR channel, from the seed point
_ROW_CONTRAST = 40.0  # BGR distance between a strip row and its surroundings


class ColorMarkError(LandmarkCatalogError):
    """A mark cannot be used: unknown landmark, outside the frame, no landmark pixels found."""


@dataclass(frozen=True)
class ColorMark:
    """One landmark marked in one frame.

    Attributes
    ----------
    frame : int
        Index of the frame in the frames given.
    landmark : str
        Catalog name.
    points : tuple of (x, y)
        Pixels on the landmark (column, row; any band).
    columns : (int, int) or None
        The first and last image column the landmark occupies.
    """

    frame: int
    landmark: str
    points: tuple[tuple[float, float], ...] = ()
    columns: tuple[int, int] | None = None


@dataclass(frozen=True)
class LearnedBox:
    """The box learned for one colour, and how it fares on the marked frames."""

    color: str
    box: HsvBox
    n_positives: int
    positive_share: float
    negative_share: float


def learn_catalog_boxes(
    frames_bgr: Sequence[NDArray[np.uint8]],
    marks: Sequence[ColorMark],
    catalog: Sequence[LandmarkSpec],
) -> tuple[tuple[LandmarkSpec, ...], list[LearnedBox]]:
    """The catalog with learned HSV boxes, and one report per colour learned.

    Colours no mark shows keep their current boxes (overrides or defaults).

    Raises
    ------
    ImageError
        A frame that is not (H, W, 3) uint8 BGR (a greyscale frame has no colours to learn).
    ColorMarkError
        A mark of an unknown landmark or frame, outside its frame, or whose pixels cannot be
        found; no marks at all.
    """
    if not marks:
        raise ColorMarkError("no marks: mark each landmark in a few frames (points or columns)")
    spec_of = {s.name: s for s in catalog}
    hsv_frames = [_hsv(f, k) for k, f in enumerate(frames_bgr)]
    positives: dict[str, list[NDArray[np.uint8]]] = {}
    regions: list[list[tuple[int, ...]]] = [[] for _ in frames_bgr]
    for mark in marks:
        spec = spec_of.get(mark.landmark)
        if spec is None:
            raise ColorMarkError(f"mark of {mark.landmark!r}: no such landmark in the catalog")
        if not 0 <= mark.frame < len(frames_bgr):
            raise ColorMarkError(f"mark of {mark.landmark!r}: no frame {mark.frame}")
        colors = spec.bands or ((spec.color,) if spec.color else ())
        if not colors:
            raise ColorMarkError(f"mark of {mark.landmark!r}: the landmark has no colour")
        bgr, hsv = frames_bgr[mark.frame], hsv_frames[mark.frame]
        if mark.columns is not None:
            found, region = _column_pixels(bgr, hsv, mark, colors)
        else:
            pixels, region = _point_pixels(bgr, hsv, mark)
            found = _by_nearest_hue(pixels, colors)
        regions[mark.frame].append(region)
        for color, px in found.items():
            positives.setdefault(color, []).append(px)
    negatives = _negatives(hsv_frames, regions)
    learned = []
    pos = {c: np.concatenate(p) for c, p in positives.items()}
    for color in sorted(pos):
        others = [p for c, p in pos.items() if c != color]
        against = np.concatenate([negatives, *others]) if others else negatives
        learned.append(_learn_box(color, pos[color], against))
    boxes = {lb.color: lb.box for lb in learned}
    out = []
    for spec in catalog:
        if spec.bands and any(c in boxes for c in spec.bands):
            current = [_current(spec, k) for k in range(len(spec.bands))]
            band_boxes = [boxes.get(c, cur) for c, cur in zip(spec.bands, current, strict=True)]
            out.append(replace(spec, band_hsv=tuple((b.lo, b.hi) for b in band_boxes)))
        elif spec.color in boxes:
            box = boxes[spec.color]
            out.append(replace(spec, hsv_lo=box.lo, hsv_hi=box.hi))
        else:
            out.append(spec)
    return tuple(out), learned


def _current(spec: LandmarkSpec, band: int) -> HsvBox:
    """Band ``band``'s box of coded ``spec`` before learning."""
    if spec.band_hsv:
        lo, hi = spec.band_hsv[band]
        return HsvBox((lo[0], lo[1], lo[2]), (hi[0], hi[1], hi[2]))
    return DEFAULT_HSV[spec.bands[band]]


def _hsv(frame: NDArray[np.uint8], index: int) -> NDArray[np.uint8]:
    if not isinstance(frame, np.ndarray) or frame.dtype != np.uint8:
        raise ImageError(f"frame {index} must be a uint8 BGR image")
    if frame.ndim != 3 or frame.shape[2] != 3:
        raise ImageError(
            f"frame {index} is greyscale (shape {frame.shape}): colours can only be learned "
            "from colour frames"
        )
    return np.asarray(cv2.cvtColor(frame, cv2.COLOR_BGR2HSV), np.uint8)


def _point_pixels(
    bgr: NDArray[np.uint8], hsv: NDArray[np.uint8], mark: ColorMark
) -> tuple[NDArray[np.uint8], tuple[int, ...]]:
    """HSV pixels (n, 3) around the mark's points and the box (x0, y0, x1, y1) of the region a
    flood fill reaches from them."""
    h, w = hsv.shape[:2]
    if not mark.points:
        raise ColorMarkError(f"mark of {mark.landmark!r}: give points or columns")
    patches, seeds = [], []
    for x, y in mark.points:
        col, row = math.floor(x), math.floor(y)
        if not (0 <= col < w and 0 <= row < h):
            raise ColorMarkError(
                f"mark of {mark.landmark!r}: point ({x:g}, {y:g}) is outside the {w}x{h} frame"
            )
        patches.append(hsv[max(row - 1, 0) : row + 2, max(col - 1, 0) : col + 2].reshape(-1, 3))
        seeds.append((col, row))
    return np.concatenate(patches), _filled_box(bgr, seeds)


def _filled_box(bgr: NDArray[np.uint8], seeds: Sequence[tuple[int, int]]) -> tuple[int, ...]:
    """Box (x0, y0, x1, y1) of what flood fills of similar colour reach from ``seeds``."""
    h, w = bgr.shape[:2]
    fill = np.zeros((h + 2, w + 2), np.uint8)
    tol = (_FLOOD_TOLERANCE,) * 3
    flags = 4 | cv2.FLOODFILL_MASK_ONLY | cv2.FLOODFILL_FIXED_RANGE | (255 << 8)
    for seed in seeds:
        cv2.floodFill(bgr, fill, seed, (0, 0, 0), tol, tol, flags)
    ys, xs = np.nonzero(fill[1:-1, 1:-1])
    return (int(xs.min()), int(ys.min()), int(xs.max()), int(ys.max()))


def _column_pixels(
    bgr: NDArray[np.uint8], hsv: NDArray[np.uint8], mark: ColorMark, colors: Sequence[str]
) -> tuple[dict[str, NDArray[np.uint8]], tuple[int, ...]]:
    """HSV pixels (n, 3) per colour of the rows of a column strip that stand out from both
    sides, and their box (x0, y0, x1, y1). Each row goes to the colour nearest its median hue;
    rows within 2 of another colour's row (two bands blend there) or of the landmark's ends
    are left out."""
    assert mark.columns is not None
    h, w = hsv.shape[:2]
    x0, x1 = sorted(int(c) for c in mark.columns)
    if x0 < 0 or x1 >= w:
        raise ColorMarkError(
            f"mark of {mark.landmark!r}: columns {x0}..{x1} are outside the {w}-column frame"
        )
    span = x1 - x0 + 1
    inner = slice(x0 + span // 4, x1 - span // 4 + 1)
    side = max(4, span)
    left = bgr[:, max(x0 - 2 - side, 0) : max(x0 - 2, 0)].astype(np.float32)
    right = bgr[:, min(x1 + 3, w) : min(x1 + 3 + side, w)].astype(np.float32)
    centre = np.median(bgr[:, inner].astype(np.float32), axis=1)
    differs = np.ones(h, np.bool_)
    for part in (left, right):
        if part.shape[1]:
            differs &= np.linalg.norm(centre - np.median(part, axis=1), axis=1) > _ROW_CONTRAST
    rows = np.flatnonzero(differs)
    if rows.size == 0:
        raise ColorMarkError(
            f"mark of {mark.landmark!r}: no row of columns {x0}..{x1} differs from its "
            "surroundings; mark points on it instead"
        )
    strip = hsv[:, inner]
    label = _nearest_color(np.median(strip[:, :, 0].astype(np.float64), axis=1), colors)
    label[~differs] = -1
    steady = np.ones(h, np.bool_)
    for shift in (-2, -1, 1, 2):
        steady &= np.roll(label, shift) == label
    steady[:2] = steady[-2:] = False
    steady &= label >= 0
    out, seeds = {}, []
    middle = (inner.start + inner.stop - 1) // 2
    for k, color in enumerate(colors):
        pick = steady & (label == k)
        if pick.any():
            out[color] = strip[pick].reshape(-1, 3)
            picked = np.flatnonzero(pick)
            seeds.append((middle, int(picked[picked.size // 2])))
    if not seeds:
        raise ColorMarkError(
            f"mark of {mark.landmark!r}: no steady colour in columns {x0}..{x1}; mark points "
            "on it instead"
        )
    return out, _filled_box(bgr, seeds)


def _nearest_color(hue: NDArray[np.float64], colors: Sequence[str]) -> NDArray[np.intp]:
    """Index (into ``colors``) of the colour whose nominal hue is nearest each of ``hue``."""
    centres = np.array([DEFAULT_HSV[c].hue_centre for c in colors])
    gap = np.abs((hue[:, None] - centres[None, :] + 90.0) % 180.0 - 90.0)
    out: NDArray[np.intp] = gap.argmin(axis=1)
    return out


def _by_nearest_hue(
    pixels: NDArray[np.uint8], colors: Sequence[str]
) -> dict[str, NDArray[np.uint8]]:
    """Pixels grouped by the colour (of ``colors``) whose nominal hue is nearest theirs."""
    if len(set(colors)) == 1:
        return {colors[0]: pixels}
    nearest = _nearest_color(pixels[:, 0].astype(np.float64), colors)
    return {c: pixels[nearest == k] for k, c in enumerate(colors) if (nearest == k).any()}


def _negatives(
    hsv_frames: Sequence[NDArray[np.uint8]], regions: Sequence[list[tuple[int, ...]]]
) -> NDArray[np.uint8]:
    """HSV pixels (n, 3) of the marked frames outside every marked region (with a margin)."""
    parts = []
    m = REGION_MARGIN_PX
    for hsv, boxes in zip(hsv_frames, regions, strict=True):
        if not boxes:
            continue
        keep = np.ones(hsv.shape[:2], np.bool_)
        for x0, y0, x1, y1 in boxes:
            keep[max(y0 - m, 0) : y1 + m + 1, max(x0 - m, 0) : x1 + m + 1] = False
        parts.append(hsv[keep])
    return np.concatenate(parts) if parts else np.zeros((0, 3), np.uint8)


def _learn_box(
    color: str, positives: NDArray[np.uint8], negatives: NDArray[np.uint8]
) -> LearnedBox:
    """The most tolerant box of the grid that meets the shares (else the one taking the fewest
    negatives among those holding 90 % of the positives, else the tightest)."""
    hue = positives[:, 0].astype(np.float64)
    angle = hue * (2.0 * math.pi / 180.0)
    centre = math.atan2(float(np.sin(angle).sum()), float(np.cos(angle).sum()))
    c = (centre * 180.0 / (2.0 * math.pi)) % 180.0
    spread = float(np.quantile(np.abs((hue - c + 90.0) % 180.0 - 90.0), 0.995))
    s_floor = float(np.quantile(positives[:, 1], 0.005))
    v_floor = float(np.quantile(positives[:, 2], 0.005))
    best: tuple[float, HsvBox, float, float] | None = None
    fallback: tuple[float, HsvBox, float, float] | None = None
    for fv in _V_FACTORS:  # value first: brightness changes most from frame to frame
        for margin in _HUE_MARGINS:
            for fs in _S_FACTORS:
                half = min(spread + margin, 89.0)
                box = HsvBox(
                    (math.floor(c - half) % 180, int(fs * s_floor), max(int(fv * v_floor), 1)),
                    (math.ceil(c + half) % 180, 255, 255),
                )
                pos_share = _share_inside(box, positives)
                neg_share = _share_inside(box, negatives)
                if pos_share >= POSITIVE_SHARE and neg_share <= NEGATIVE_SHARE:
                    return LearnedBox(color, box, len(positives), pos_share, neg_share)
                if pos_share >= 0.9 and (fallback is None or neg_share < fallback[0]):
                    fallback = (neg_share, box, pos_share, neg_share)
                best = (neg_share, box, pos_share, neg_share)
    chosen = fallback or best
    assert chosen is not None
    return LearnedBox(color, chosen[1], len(positives), chosen[2], chosen[3])


def _share_inside(box: HsvBox, pixels: NDArray[np.uint8]) -> float:
    """Share of HSV ``pixels`` (n, 3) inside ``box``."""
    if len(pixels) == 0:
        return 0.0
    h, s, v = pixels[:, 0], pixels[:, 1], pixels[:, 2]
    above, below = h >= box.lo[0], h <= box.hi[0]
    in_h = (above | below) if box.wraps else (above & below)
    inside = in_h & (s >= box.lo[1]) & (s <= box.hi[1]) & (v >= box.lo[2]) & (v <= box.hi[2])
    return float(inside.mean())
