"""Bearings of catalog landmarks in panoramic frames (unwrapped or omni calibration)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from data_schemas.calibration import Calibration
from data_schemas.errors import ImageError
from data_schemas.session import LandmarkSpec
from pipeline.bearings.blobs import (
    Blob,
    component_blobs,
    is_fringe,
    profile_blobs,
    profile_of_mask,
)
from pipeline.bearings.classify import ColorClassifier
from pipeline.bearings.color_classes import LandmarkCatalogError, hsv_box_for
from pipeline.bearings.detection import Detection, detection_from_blobs
from pipeline.bearings.layout import OmniLayout, make_layout

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
        Not an array, wrong dtype, not 3-channel BGR, or a size other than the calibration's.
    """
    if not isinstance(image_bgr, np.ndarray):
        raise ImageError(f"image must be a numpy array, got {type(image_bgr).__name__}")
    if image_bgr.dtype != np.uint8:
        raise ImageError(f"image must be uint8 BGR, got dtype {image_bgr.dtype}")
    if image_bgr.ndim != 3 or image_bgr.shape[2] != 3:
        raise ImageError(f"image must have shape (H, W, 3) (BGR), got {image_bgr.shape}")
    h, w = image_bgr.shape[:2]
    if (w, h) != (calibration.width, calibration.height):
        raise ImageError(
            f"image is {w}x{h} (width x height) but the camera calibration is "
            f"{calibration.width}x{calibration.height}; use the calibration of this camera"
        )
    return image_bgr


class BearingExtractor:
    """Colour-threshold landmarks and measure their bearings, frame by frame or in batches.

    Lookup tables for the calibration and the colour classes are built once here.

    Parameters
    ----------
    calibration : UnwrappedCalibration or OmniCalibration
        Maps image positions to bearings; frames must have its size.
    catalog : sequence of LandmarkSpec
        Landmarks (unique names) with colour names of ``data_schemas.colors`` and optional
        HSV overrides.
    min_pixels : int, optional
        Smallest blob reported as visible, pixels; default :data:`MIN_BLOB_PIXELS` at any size.
    method : {"profile", "components"}
        Blobs as runs of the angular profile (column sums / ring sums, fast) or as 8-connected
        components (slower; separates blobs stacked in the same bearings).
    max_gap_bins : int, optional
        Profile runs this close (empty bins between them) are one blob; default one column
        (unwrapped) or one pixel's span at ``r_min`` (omni).

    Raises
    ------
    LandmarkCatalogError
        Duplicate names, unknown colour name or a malformed HSV override.
    """

    def __init__(
        self,
        calibration: Calibration,
        catalog: Sequence[LandmarkSpec],
        *,
        min_pixels: int | None = None,
        method: Method = "profile",
        max_gap_bins: int | None = None,
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
        self._boxes = [hsv_box_for(spec) for spec in catalog]
        self._classifier = ColorClassifier(self._boxes)

    def extract(self, image_bgr: NDArray[np.uint8]) -> dict[str, Detection]:
        """Detections of every catalog landmark in one BGR frame, keyed by name."""
        planes = self._classify(self._region(check_image(image_bgr, self.calibration)), 1)
        return self._detect(planes)

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
                results.append(self._detect([p[rows] for p in planes]))
        return results

    def masks(self, image_bgr: NDArray[np.uint8]) -> dict[str, NDArray[np.bool_]]:
        """Per landmark, the (H, W) boolean mask of its colour class (for display)."""
        image = check_image(image_bgr, self.calibration)
        return self._masks(self._classify(self._region(image), 1), image.shape[:2])

    def extract_with_masks(
        self, image_bgr: NDArray[np.uint8]
    ) -> tuple[dict[str, Detection], dict[str, NDArray[np.bool_]]]:
        """:meth:`extract` and :meth:`masks` of one frame, classifying its pixels once."""
        image = check_image(image_bgr, self.calibration)
        planes = self._classify(self._region(image), 1)
        return self._detect(planes), self._masks(planes, image.shape[:2])

    # ------------------------------------------------------------------ internals
    def _crop(self) -> tuple[slice, slice]:
        if isinstance(self._layout, OmniLayout):
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
        out = {}
        for name, slot in zip(self.names, self._classifier.slots, strict=True):
            full = np.zeros(shape, np.bool_)
            full[self._crop()] = (planes[slot.plane] & slot.bit) != 0
            out[name] = full
        return out

    def _detect(self, planes: list[NDArray[np.uint8]]) -> dict[str, Detection]:
        slots = self._classifier.slots
        found = [
            self._blobs(np.bitwise_and(planes[slot.plane], np.uint8(slot.bit)), slot.bit)
            for slot in slots
        ]
        fringe = {
            "max_width_rad": self._layout.fringe_width_rad,
            "bin_width_rad": self._layout.bin_width_rad,
        }
        out = {}
        for k, name in enumerate(self.names):
            blobs, largest = found[k]
            others = [
                b for j, (bj, _) in enumerate(found) if self._boxes[j] != self._boxes[k] for b in bj
            ]
            kept = [b for b in blobs if not is_fringe(b, others, **fringe)]
            out[name] = detection_from_blobs(
                name, kept, largest, min_pixels=self.min_pixels, n_fringes=len(blobs) - len(kept)
            )
        return out

    def _blobs(self, mask: NDArray[np.uint8], value: int) -> tuple[list[Blob], int]:
        if self.method == "components":
            return component_blobs(mask, self._layout, min_pixels=self.min_pixels)
        profile = profile_of_mask(mask, value, self._layout)
        return profile_blobs(profile, min_pixels=self.min_pixels, max_gap_bins=self.max_gap_bins)
