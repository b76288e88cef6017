"""Bearing extraction: colour-threshold landmarks in panoramic frames, measure their bearings.

Pure (arrays in, arrays out). See ``docs/bearings.md`` for colour classes, calibration models,
accuracy and speed.
"""

from pipeline.bearings.color_classes import DEFAULT_HSV, HsvBox, LandmarkCatalogError, hsv_box_for
from pipeline.bearings.decode import decode_frame
from pipeline.bearings.detection import Detection
from pipeline.bearings.extractor import BearingExtractor, check_image

__all__ = [
    "DEFAULT_HSV",
    "BearingExtractor",
    "Detection",
    "HsvBox",
    "LandmarkCatalogError",
    "check_image",
    "decode_frame",
    "hsv_box_for",
]
