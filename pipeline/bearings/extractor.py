"""Bearings of catalog landmarks in frames of an unwrapped, omni or pinhole calibration.

Landmarks are found by class: a colour (blobs of its colour class) or a band code (stacks of
band colours read along columns or rays, :mod:`pipeline.bearings.bands`). Every blob of a class
is reported; a landmark gets a bearing only when its class is its own.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import cv2
import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad
from data_schemas.calibration import Calibration
from data_schemas.errors import ImageError
from data_schemas.session import LandmarkSpec
from pipeline.bearings.bands import BandDecoder
from pipeline.bearings.blobs import (
    Blob,
    component_blobs,
    is_covered,
    is_fringe,
    is_squeezed,
    profiles_blobs,
    profiles_of_bits,
)
from pipeline.bearings.classify import ClassBit, ColorClassifier
from pipeline.bearings.color_classes import HsvBox, LandmarkCatalogError, landmark_classes
from pipeline.bearings.detection import ClassSightings, Detection, detection_of
from pipeline.bearings.layout import OmniLayout, PinholeLayout, PixelLayout, make_layout
from pipeline.bearings.size_gate import size_gate

#: Default ``min_pixels``: a blob must be at least a 2 x 2 pixel patch, whatever the image size.
#: A landmark far away is a sliver a pixel or two wide and a few rows tall at any resolution,
#: so the floor is a pixel count, not a share of the image (docs/bearings.md, detection range).
MIN_BLOB_PIXELS = 4
_BATCH_PIXELS = 300_000  # frames classified together per OpenCV call (cache-sized)

Method = Literal["profile", "components"]


def check_image(image_bgr: object, calibration: Calibration) -> NDArray[np.uint8]:
    """Return ``image_bgr`` as an (H, W, 3) uint8 array matching ``calibration``, or raise.

    Raises
    ------
    ImageError
        Not an array, wrong dtype, not 3-channel BGR, a greyscale frame (one channel, or three
        equal channels that are not uniform: landmarks are found by colour), or a size other
        than the calibration's.
    """
    if not isinstance(image_bgr, np.ndarray):
        raise ImageError(f"image must be a numpy array, got {type(image_bgr).__name__}")
    if image_bgr.dtype != np.uint8:
        raise ImageError(f"image must be uint8 BGR, got dtype {image_bgr.dtype}")
    if image_bgr.ndim == 2 or (image_bgr.ndim == 3 and image_bgr.shape[2] == 1):
        raise ImageError(f"image is greyscale (shape {image_bgr.shape}): {_GREY}")
    if image_bgr.ndim != 3 or image_bgr.shape[2] != 3:
        raise ImageError(f"image must have shape (H, W, 3) (BGR), got {image_bgr.shape}")
    h, w = image_bgr.shape[:2]
    if (w, h) != (calibration.width, calibration.height):
        raise ImageError(
            f"image is {w}x{h} (width x height) but the camera calibration is "
            f"{calibration.width}x{calibration.height}; use the calibration of this camera"
        )
    if _is_grey(image_bgr):
        raise ImageError(f"frame is greyscale (its three channels are equal): {_GREY}")
    return image_bgr


_GREY = (
    "landmarks are found by their colours, which a greyscale frame does not have; record "
    "colour frames"
)


def _is_grey(image: NDArray[np.uint8]) -> bool:
    """True if the three channels are equal and the frame is not uniform (a black or blank
    frame from a colour camera is not taken for greyscale)."""
    blue, green = image[..., 0], image[..., 1]
    if not (np.array_equal(blue, green) and np.array_equal(green, image[..., 2])):
        return False
    return int(blue.max()) - int(blue.min()) > 8


#: A code whose band colours' single-colour blobs lie more than this share of its width apart
#: in bearing is those landmarks side by side, not one coded landmark.
SIDE_BY_SIDE_SHARE = 0.25


class BearingExtractor:
    """Find catalog landmarks and measure their bearings, frame by frame or in batches.

    Lookup tables for the calibration and the colour classes are built once here.

    Parameters
    ----------
    calibration : UnwrappedCalibration, OmniCalibration or PinholeCalibration
        Maps image positions to bearings; frames must have its size.
    catalog : sequence of LandmarkSpec
        Landmarks (unique names): a colour name of ``data_schemas.colors`` (optional HSV
        override) or a band code (two or more colour names, top to bottom). Several landmarks
        may share a class; then none of them gets a bearing from :meth:`extract` (their blobs
        are in :meth:`extract_classes` and in each :class:`Detection`'s ``blobs``).
    min_pixels : int, optional
        Smallest blob reported, pixels; default :data:`MIN_BLOB_PIXELS` at any size.
    method : {"profile", "components"}
        Single-colour blobs as runs of the angular profile (column sums / ring sums, fast) or
        as 8-connected components (slower; separates blobs stacked in the same bearings).
    max_gap_bins : int, optional
        Profile runs this close (empty bins between them) are one blob; default one column
        (unwrapped) or one pixel's span at ``r_min`` (omni).
    range_m : (float, float), optional
        Nearest and farthest distance (m) landmarks can be seen from: with the catalog's
        landmark widths, blobs of a size no landmark of their class can have are rejected
        (:mod:`pipeline.bearings.size_gate`; ``ClassSightings.rejected``).

    Raises
    ------
    LandmarkCatalogError
        Duplicate names, unknown colour name, a malformed HSV override or band code.
    """

    def __init__(
        self,
        calibration: Calibration,
        catalog: Sequence[LandmarkSpec],
        *,
        min_pixels: int | None = None,
        method: Method = "profile",
        max_gap_bins: int | None = None,
        range_m: tuple[float, float] | None = None,
    ) -> None:
        names = [spec.name for spec in catalog]
        if len(set(names)) != len(names):
            raise LandmarkCatalogError(f"landmark names must be unique, got {names}")
        if method not in ("profile", "components"):
            raise ValueError(f"method must be 'profile' or 'components', got {method!r}")
        self.calibration = calibration
        self.names = names
        self.method = method
        self.min_pixels = MIN_BLOB_PIXELS if min_pixels is None else min_pixels
        if self.min_pixels < 1:
            raise ValueError(f"min_pixels must be at least 1, got {self.min_pixels}")
        self._layout = make_layout(calibration)
        self.max_gap_bins = self._layout.gap_bins if max_gap_bins is None else max_gap_bins
        self.classes = landmark_classes(catalog)
        self._class_of = {n: c.label for c in self.classes for n in c.landmarks}
        spec_of = {spec.name: spec for spec in catalog}
        self._gates = {
            c.label: size_gate(
                [spec_of[n] for n in c.landmarks], range_m, self._layout.bin_width_rad
            )
            for c in self.classes
        }
        # one classifier slot per distinct HSV box, shared by every class that uses it
        boxes: list[HsvBox] = []
        for cls in self.classes:
            boxes += [b for b in cls.boxes if b not in boxes]
        self._boxes = boxes
        self._classifier = ColorClassifier(boxes)
        self._singles = [c for c in self.classes if not c.coded]
        self._single_slots = [
            (slot.plane, slot.bit) for slot in (self._slot(c.boxes[0]) for c in self._singles)
        ]
        self._coded = [c for c in self.classes if c.coded]
        self._decoder: BandDecoder | None = None
        if self._coded:
            band_boxes = [b for c in self._coded for b in c.boxes]
            band_boxes = [b for i, b in enumerate(band_boxes) if b not in band_boxes[:i]]
            self._label_luts = _label_luts(
                [self._slot(b) for b in band_boxes], self._classifier.n_planes
            )
            self._decoder = BandDecoder(
                self._layout,
                [b.hue_centre for b in band_boxes],
                [tuple(band_boxes.index(b) for b in c.boxes) for c in self._coded],
                min_pixels=self.min_pixels,
                max_gap_bins=self.max_gap_bins,
            )

    def extract(self, image_bgr: NDArray[np.uint8]) -> dict[str, Detection]:
        """Detections of every catalog landmark in one BGR frame, keyed by name."""
        return self.detections(self.extract_classes(image_bgr))

    def extract_classes(self, image_bgr: NDArray[np.uint8]) -> dict[str, ClassSightings]:
        """Every blob of every landmark class in one BGR frame, keyed by class label."""
        planes = self._classify(self._region(check_image(image_bgr, self.calibration)), 1)
        return self._sightings(planes)

    def detections(self, sightings: dict[str, ClassSightings]) -> dict[str, Detection]:
        """Per catalog landmark (catalog order), its report from its class's sightings."""
        return {
            name: detection_of(name, sightings[self._class_of[name]], min_pixels=self.min_pixels)
            for name in self.names
        }

    def extract_batch(
        self, images_bgr: Sequence[NDArray[np.uint8]] | NDArray[np.uint8]
    ) -> list[dict[str, Detection]]:
        """Detections for many frames (a sequence or an (N, H, W, 3) array), in order.

        Frames are classified several at a time, which saves per-call overhead on small frames.
        """
        frames = [check_image(image, self.calibration) for image in images_bgr]
        if not frames:
            return []
        region_h, region_w = self._region(frames[0]).shape[:2]
        per_call = max(1, _BATCH_PIXELS // (region_h * region_w))
        results: list[dict[str, Detection]] = []
        for first in range(0, len(frames), per_call):
            chunk = frames[first : first + per_call]
            stack = np.concatenate([self._region(f) for f in chunk], axis=0)
            planes = self._classify(stack, len(chunk))
            for i in range(len(chunk)):
                rows = slice(i * region_h, (i + 1) * region_h)
                results.append(self.detections(self._sightings([p[rows] for p in planes])))
        return results

    @property
    def field_of_view_rad(self) -> tuple[float, float] | None:
        """Bearings (rad, robot frame) of the right and left edges of a pinhole camera's view,
        ``(lo, hi)`` (a bearing ``b`` is in view when ``wrap(b - lo) <= hi - lo``); None for a
        panoramic camera."""
        if isinstance(self._layout, PinholeLayout):
            return self._layout.field_of_view_rad
        return None

    def masks(self, image_bgr: NDArray[np.uint8]) -> dict[str, NDArray[np.bool_]]:
        """Per landmark, the (H, W) boolean mask of its class's colours (for display)."""
        image = check_image(image_bgr, self.calibration)
        return self._masks(self._classify(self._region(image), 1), image.shape[:2])

    def extract_with_masks(
        self, image_bgr: NDArray[np.uint8]
    ) -> tuple[dict[str, Detection], dict[str, NDArray[np.bool_]]]:
        """:meth:`extract` and :meth:`masks` of one frame, classifying its pixels once."""
        image = check_image(image_bgr, self.calibration)
        planes = self._classify(self._region(image), 1)
        return self.detections(self._sightings(planes)), self._masks(planes, image.shape[:2])

    # ------------------------------------------------------------------ internals
    def _slot(self, box: HsvBox) -> ClassBit:
        return self._classifier.slots[self._boxes.index(box)]

    def _crop(self) -> tuple[slice, slice]:
        if isinstance(self._layout, PixelLayout):
            return self._layout.crop
        return (slice(None), slice(None))

    def _region(self, image: NDArray[np.uint8]) -> NDArray[np.uint8]:
        """The part of a frame that can hold bearings (omni: the ring's bounding box)."""
        return image[self._crop()]

    def _classify(self, stack: NDArray[np.uint8], n_frames: int) -> list[NDArray[np.uint8]]:
        valid = None
        if isinstance(self._layout, OmniLayout):
            ring = self._layout.ring
            valid = ring if n_frames == 1 else np.tile(ring, (n_frames, 1))
        return self._classifier.classify(stack, valid)

    def _masks(
        self, planes: list[NDArray[np.uint8]], shape: tuple[int, ...]
    ) -> dict[str, NDArray[np.bool_]]:
        """Full-frame (H, W) class masks from the classifier planes of the region."""
        by_label = {}
        for cls in self.classes:
            full = np.zeros(shape, np.bool_)
            for box in cls.boxes:
                slot = self._slot(box)
                full[self._crop()] |= (planes[slot.plane] & slot.bit) != 0
            by_label[cls.label] = full
        return {name: by_label[self._class_of[name]] for name in self.names}

    def _sightings(self, planes: list[NDArray[np.uint8]]) -> dict[str, ClassSightings]:
        found = self._single_blobs(planes)
        coded: list[tuple[list[Blob], int]] = []
        if self._decoder is not None:
            labels = _labels(planes, self._label_luts)
            coded = self._decoder.decode(self._decoder.grid(labels))
            coded = [
                ([b for b in blobs if not self._side_by_side(b, cls.colors, found)], largest)
                for cls, (blobs, largest) in zip(self._coded, coded, strict=True)
            ]
        code_blobs = [b for blobs, _ in coded for b in blobs]
        fringe = {
            "max_width_rad": self._layout.fringe_width_rad,
            "bin_width_rad": self._layout.bin_width_rad,
        }
        out = {}
        for k, cls in enumerate(self._singles):
            blobs, largest = found[k]
            others = [
                b
                for j, (bj, _) in enumerate(found)
                if self._singles[j].boxes != cls.boxes
                for b in bj
            ]
            kept = [b for b in blobs if not is_fringe(b, others + code_blobs, **fringe)]
            n_fringes = len(blobs) - len(kept)
            kept = [b for b in kept if not any(self._within(b, c) for c in code_blobs)]
            kept, rejected = self._gate(cls.label, kept)
            out[cls.label] = ClassSightings(
                cls.label, cls.landmarks, tuple(kept), largest, n_fringes, rejected=rejected
            )
        single_blobs = [(b, c.colors) for c in self._singles for b in out[c.label].blobs]
        for k, (cls, (blobs, largest)) in enumerate(zip(self._coded, coded, strict=True)):
            other_codes = [b for j, (bj, _) in enumerate(coded) if j != k for b in bj]
            pairs = single_blobs + [
                (b, self._coded[j].colors) for j, (bj, _) in enumerate(coded) if j != k for b in bj
            ]
            others = [b for b, _ in pairs]
            ends = {cls.colors[0], cls.colors[-1]}
            kin = [bool(ends & {colors[0], colors[-1]}) for _, colors in pairs]
            kept = [
                b
                for b in blobs
                if not is_fringe(b, others, **fringe)
                and not is_squeezed(b, others, kin=kin, **fringe)
                and not is_covered(b, other_codes)
            ]
            n_fringes = len(blobs) - len(kept)
            kept, rejected = self._gate(cls.label, kept)
            out[cls.label] = ClassSightings(
                cls.label, cls.landmarks, tuple(kept), largest, n_fringes, True, rejected
            )
        return out

    def _gate(
        self, label: str, blobs: list[Blob]
    ) -> tuple[list[Blob], tuple[tuple[Blob, str], ...]]:
        """``blobs`` split into those a landmark of class ``label`` can be and the others, each
        with the reason: of a size no landmark of the class can have, or (pinhole) cut by the
        image's edge."""
        gate = self._gates[label]
        layout = self._layout
        edge = layout if isinstance(layout, PinholeLayout) else None
        if gate is None and edge is None:
            return blobs, ()
        why = [
            "cut by the image's edge"
            if edge is not None and edge.cut_by_edge(b.bearing_rad, b.width_rad)
            else (gate.problem(b) if gate is not None else None)
            for b in blobs
        ]
        kept = [b for b, w in zip(blobs, why, strict=True) if w is None]
        return kept, tuple((b, w) for b, w in zip(blobs, why, strict=True) if w is not None)

    def _side_by_side(
        self, code: Blob, colors: tuple[str, ...], found: list[tuple[list[Blob], int]]
    ) -> bool:
        """True if coded ``code`` (band ``colors``) is single-colour landmarks of its band
        colours side by side: for every band colour a blob of a single-colour class overlaps
        it, and the largest of each colour lie more than :data:`SIDE_BY_SIDE_SHARE` of the
        code's width apart in bearing. The bands of one landmark share its bearings; two
        landmarks one behind the other, seen where their edges meet, read as a stack of their
        colours only along the rays (omni) or columns where they overlap."""
        bearings = []
        for color in dict.fromkeys(colors):
            near = [
                b
                for cls, (blobs, _) in zip(self._singles, found, strict=True)
                if cls.colors == (color,)
                for b in blobs
                if abs(wrap_rad(b.bearing_rad - code.bearing_rad))
                <= 0.5 * (b.width_rad + code.width_rad)
            ]
            if not near:
                return False
            bearings.append(max(near, key=lambda b: b.n_pixels).bearing_rad)
        spread = max(abs(wrap_rad(a - b)) for a in bearings for b in bearings)
        return spread > SIDE_BY_SIDE_SHARE * code.width_rad

    def _within(self, blob: Blob, code: Blob) -> bool:
        """True if single-colour ``blob`` lies inside coded ``code``'s bearings: one of its bands
        or a blend of two (not a landmark of its own)."""
        gap = abs(wrap_rad(blob.bearing_rad - code.bearing_rad))
        reach = 0.5 * (code.width_rad - blob.width_rad) + self._layout.bin_width_rad
        return gap <= reach and blob.n_pixels <= code.n_pixels

    def _single_blobs(self, planes: list[NDArray[np.uint8]]) -> list[tuple[list[Blob], int]]:
        """Per single-colour class: its blobs (largest first) and its largest run's pixels."""
        if self.method == "components":
            return [
                component_blobs(
                    np.bitwise_and(planes[p], np.uint8(bit)),
                    self._layout,
                    min_pixels=self.min_pixels,
                )
                for p, bit in self._single_slots
            ]
        profiles = profiles_of_bits(planes, self._single_slots, self._layout)
        return profiles_blobs(profiles, min_pixels=self.min_pixels, max_gap_bins=self.max_gap_bins)


def _label_luts(slots: list[ClassBit], n_planes: int) -> list[NDArray[np.uint8]]:
    """Per classifier plane, a 256-entry table: class bits -> band colour label (0 = none)."""
    luts = [np.zeros(256, np.uint8) for _ in range(n_planes)]
    bits = np.arange(256)
    for k in reversed(range(len(slots))):  # the lowest band colour index wins overlaps
        slot = slots[k]
        luts[slot.plane][(bits & slot.bit) != 0] = k + 1
    return luts


def _labels(planes: list[NDArray[np.uint8]], luts: list[NDArray[np.uint8]]) -> NDArray[np.uint8]:
    """Band colour label of every pixel (region-sized, 0 = none) from the classifier planes."""
    out: NDArray[np.uint8] | None = None
    for plane, lut in zip(planes, luts, strict=True):
        if not lut.any():
            continue
        labels = np.asarray(cv2.LUT(plane, lut), np.uint8)
        out = labels if out is None else np.where(out > 0, out, labels)
    assert out is not None
    return out
