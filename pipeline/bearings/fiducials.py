"""Fiducial markers (ArUco, AprilTag) as landmarks: OpenCV's aruco detector, a bearing per tag.

A landmark ``{"name": "T7", "tag": 7}`` is the marker of id 7 in the session's
``tag_dictionary`` (OpenCV's predefined dictionaries: ``4x4_50`` ... ``6x6_1000``,
``aruco_original``, ``apriltag_16h5`` ... ``apriltag_36h11``). Its ids are unique whatever the
light, and greyscale frames carry them as well as colour ones. The bearing is that of the tag's
centre (the mean of its four corners) through the camera's calibration; the width is the
angular extent of its corners. A catalog of tags only: a catalog that mixes tags and colours is
refused (one detector per log).
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad
from data_schemas.calibration import Calibration, OmniCalibration, UnwrappedCalibration
from data_schemas.errors import ImageError
from data_schemas.session import LandmarkSpec
from pipeline.bearings.blobs import Blob
from pipeline.bearings.color_classes import LandmarkCatalogError
from pipeline.bearings.detection import ClassSightings, Detection, detection_of
from pipeline.bearings.extractor import BearingExtractor
from pipeline.bearings.pinhole import pixel_bearings

#: ``tag_dictionary`` names -> OpenCV's predefined dictionaries.
TAG_DICTIONARIES: dict[str, int] = {
    **{
        f"{n}x{n}_{k}": getattr(cv2.aruco, f"DICT_{n}X{n}_{k}")
        for n in (4, 5, 6)
        for k in (50, 100, 250, 1000)
    },
    "aruco_original": cv2.aruco.DICT_ARUCO_ORIGINAL,
    "apriltag_16h5": cv2.aruco.DICT_APRILTAG_16h5,
    "apriltag_25h9": cv2.aruco.DICT_APRILTAG_25h9,
    "apriltag_36h10": cv2.aruco.DICT_APRILTAG_36h10,
    "apriltag_36h11": cv2.aruco.DICT_APRILTAG_36h11,
}


class TagExtractor:
    """Find a catalog's fiducial markers in frames and measure their bearings.

    The same calls as :class:`pipeline.bearings.BearingExtractor` that the replay uses:
    :meth:`extract` and :meth:`extract_with_masks`; frames may be (H, W), (H, W, 1) or BGR.

    Raises
    ------
    LandmarkCatalogError
        A landmark without a tag, two landmarks with one tag, an unknown dictionary.
    """

    def __init__(
        self, calibration: Calibration, catalog: Sequence[LandmarkSpec], dictionary: str
    ) -> None:
        kind = TAG_DICTIONARIES.get(dictionary)
        if kind is None:
            raise LandmarkCatalogError(
                f"unknown tag dictionary {dictionary!r}; known: {', '.join(TAG_DICTIONARIES)}"
            )
        untagged = [s.name for s in catalog if s.tag is None]
        if untagged:
            raise LandmarkCatalogError(
                f"landmarks {', '.join(untagged)} have no tag: a catalog is either fiducial "
                "tags or colours, not both"
            )
        self.calibration = calibration
        self.names = [s.name for s in catalog]
        self._name_of = {int(s.tag): s.name for s in catalog if s.tag is not None}
        if len(self._name_of) != len(self.names):
            raise LandmarkCatalogError("two landmarks have the same tag; give each its own id")
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        self._detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(kind), params)

    @property
    def field_of_view_rad(self) -> tuple[float, float] | None:
        """As :attr:`BearingExtractor.field_of_view_rad` (None here: given by the layout there)."""
        return None

    def extract(self, image: NDArray[np.uint8]) -> dict[str, Detection]:
        """Detections of every catalog tag in one frame, keyed by name."""
        return self.extract_with_masks(image)[0]

    def extract_with_masks(
        self, image: NDArray[np.uint8]
    ) -> tuple[dict[str, Detection], dict[str, NDArray[np.bool_]]]:
        """:meth:`extract` and, per landmark, the (H, W) mask of its tag's quadrilateral."""
        grey = self._grey(image)
        corners, ids, _ = self._detector.detectMarkers(grey)
        found: dict[str, list[tuple[Blob, NDArray[np.float64]]]] = {n: [] for n in self.names}
        for quad, tag in zip(corners, [] if ids is None else ids.ravel(), strict=True):
            name = self._name_of.get(int(tag))
            if name is not None:
                xy = np.asarray(quad, np.float64).reshape(4, 2) + 0.5  # continuous coordinates
                found[name].append((self._blob(xy), xy))
        detections, masks = {}, {}
        for name, seen in found.items():
            seen.sort(key=lambda b: -b[0].n_pixels)
            blobs = tuple(b for b, _ in seen)
            largest = blobs[0].n_pixels if blobs else 0
            det = detection_of(name, ClassSightings(name, (name,), blobs, largest), min_pixels=1)
            if not det.visible:
                det = Detection(name, False, None, 0.0, 0.0, 0, 0, "tag not seen")
            detections[name] = det
            mask = np.zeros(grey.shape, np.uint8)
            for _, xy in seen:
                cv2.fillConvexPoly(mask, np.round(xy - 0.5).astype(np.int32), 1)
            masks[name] = mask.astype(np.bool_)
        return detections, masks

    def _grey(self, image: object) -> NDArray[np.uint8]:
        if not isinstance(image, np.ndarray) or image.dtype != np.uint8:
            raise ImageError("image must be a uint8 numpy array (greyscale or BGR)")
        if image.ndim == 3 and image.shape[2] == 3:
            image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        elif image.ndim == 3 and image.shape[2] == 1:
            image = image[..., 0]
        if image.ndim != 2:
            raise ImageError(f"image must be (H, W) greyscale or (H, W, 3) BGR, got {image.shape}")
        h, w = image.shape
        cal = self.calibration
        if (w, h) != (cal.width, cal.height):
            raise ImageError(
                f"image is {w}x{h} (width x height) but the camera calibration is "
                f"{cal.width}x{cal.height}; use the calibration of this camera"
            )
        return np.asarray(image, np.uint8)

    def _blob(self, corners: NDArray[np.float64]) -> Blob:
        """The tag's blob: area (pixels), bearing of its centre, extent of its corners."""
        centre = corners.mean(axis=0)
        points = np.vstack([centre, corners])
        bearing = pixel_bearing(self.calibration, points[:, 0], points[:, 1])
        spread = wrap_rad(bearing[1:] - bearing[0])
        area = 0.5 * abs(
            float(np.dot(corners[:, 0], np.roll(corners[:, 1], 1)))
            - float(np.dot(corners[:, 1], np.roll(corners[:, 0], 1)))
        )
        return Blob(max(1, round(area)), float(bearing[0]), float(spread.max() - spread.min()))


def pixel_bearing(
    calibration: Calibration, x: NDArray[np.float64], y: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Bearing (rad, robot frame) of continuous pixel coordinates, for any camera model."""
    if isinstance(calibration, UnwrappedCalibration):
        return calibration.bearing_of_column(x)
    if isinstance(calibration, OmniCalibration):
        return calibration.bearing_of_pixel(x, y)
    return pixel_bearings(calibration, x, y)


def make_extractor(
    calibration: Calibration,
    catalog: Sequence[LandmarkSpec],
    *,
    range_m: tuple[float, float] | None = None,
    tag_dictionary: str = "4x4_50",
) -> BearingExtractor | TagExtractor:
    """The extractor of a catalog: fiducial tags (:class:`TagExtractor`) or colours and band
    codes (:class:`~pipeline.bearings.extractor.BearingExtractor`, with the size gate)."""
    if any(s.tag is not None for s in catalog):
        return TagExtractor(calibration, catalog, tag_dictionary)
    return BearingExtractor(calibration, catalog, range_m=range_m)
