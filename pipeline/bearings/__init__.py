"""Bearing extraction: find landmarks by colour or band code in frames of a panoramic or pinhole
camera, measure their bearings.

Pure (arrays in, arrays out). See ``docs/bearings.md`` for colour classes, calibration models,
accuracy and speed.
"""

from pipeline.bearings.blobs import Blob
from pipeline.bearings.color_classes import (
    DEFAULT_HSV,
    HsvBox,
    LandmarkCatalogError,
    LandmarkClass,
    hsv_box_for,
    landmark_classes,
)
from pipeline.bearings.decode import decode_frame
from pipeline.bearings.detection import ClassSightings, Detection
from pipeline.bearings.extractor import BearingExtractor, check_image
from pipeline.bearings.fiducials import TagExtractor, make_extractor
from pipeline.bearings.pinhole import camera_view_rad, pixel_bearings

__all__ = [
    "DEFAULT_HSV",
    "BearingExtractor",
    "Blob",
    "ClassSightings",
    "Detection",
    "HsvBox",
    "LandmarkCatalogError",
    "LandmarkClass",
    "TagExtractor",
    "camera_view_rad",
    "check_image",
    "decode_frame",
    "hsv_box_for",
    "landmark_classes",
    "make_extractor",
    "pixel_bearings",
]
