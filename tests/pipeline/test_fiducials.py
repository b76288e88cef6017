"""Fiducial tags as landmarks: OpenCV's aruco detector, a bearing per tag centre.

Oracle: tags 10 cm wide, 1.2-2 m away at known bearings, facing the camera; their corners
projected by ``cv2.projectPoints`` and the marker image warped onto them
(``cv2.warpPerspective``), so the true bearing of each centre is ``atan2(-x, z)`` of its 3-D
point.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from data_schemas.calibration import PinholeCalibration, UnwrappedCalibration
from data_schemas.errors import SchemaError
from data_schemas.session import LandmarkSpec, session_from_doc
from pipeline.bearings import LandmarkCatalogError, TagExtractor, make_extractor

DEG = math.pi / 180.0
CAL = PinholeCalibration(640, 480, 560.0, 560.0, 319.5, 239.5, offset_rad=10 * DEG)
TAGS = {3: (20.0, 1.5), 7: (-5.0, 1.2), 11: (0.0, 2.0)}  # id -> (bearing deg from axis, range m)


def _scene(rng: np.random.Generator) -> tuple[np.ndarray, dict[int, float]]:
    """A greyscale frame with the tags pasted, and each tag's true bearing (robot frame)."""
    image = rng.integers(90, 140, (CAL.height, CAL.width), dtype=np.uint8)
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    truth = {}
    for tag, (b_deg, r_m) in TAGS.items():
        b = b_deg * DEG
        centre = r_m * np.array([-math.sin(b), -0.05, math.cos(b)])
        right = np.array([math.cos(b), 0.0, math.sin(b)])  # in the tag's plane, facing us
        down = np.array([0.0, 1.0, 0.0])
        half = 0.05 * 6 / 4  # the marker image's white border: 4 cells + 1 each side
        corners = [
            centre + half * (sx * right + sy * down)
            for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))
        ]
        uv, _ = cv2.projectPoints(
            np.array(corners), np.zeros(3), np.zeros(3), CAL.camera_matrix, None
        )
        marker = cv2.aruco.generateImageMarker(dictionary, tag, 120)
        marker = cv2.copyMakeBorder(marker, 30, 30, 30, 30, cv2.BORDER_CONSTANT, value=255)
        src = np.array([[0, 0], [179, 0], [179, 179], [0, 179]], np.float32)
        warp = cv2.getPerspectiveTransform(src, uv.reshape(4, 2).astype(np.float32))
        size = (CAL.width, CAL.height)
        drawn = cv2.warpPerspective(marker, warp, size, flags=cv2.INTER_LINEAR)
        cover = cv2.warpPerspective(np.full_like(marker, 255), warp, size, flags=cv2.INTER_LINEAR)
        alpha = cover.astype(np.float32) / 255.0
        image = (alpha * drawn + (1 - alpha) * image).astype(np.uint8)
        truth[tag] = CAL.offset_rad + math.atan2(-centre[0], centre[2])
    return image, truth


def _catalog() -> list[LandmarkSpec]:
    return [LandmarkSpec(f"T{t}", None, tag=t) for t in (3, 7, 11, 30)]


def test_each_tag_reads_at_its_centre_in_grey_and_colour_frames() -> None:
    image, truth = _scene(np.random.default_rng(2))
    extractor = make_extractor(CAL, _catalog())
    assert isinstance(extractor, TagExtractor)
    for frame in (image, image[..., None], cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)):
        found = extractor.extract(frame)
        for tag, bearing in truth.items():
            got = found[f"T{tag}"].bearing_rad
            assert got is not None, tag
            assert abs(math.remainder(got - bearing, 2 * math.pi)) < 0.05 * DEG, tag
        assert found["T30"].bearing_rad is None and found["T30"].reason == "tag not seen"
    detections, masks = extractor.extract_with_masks(image)
    assert masks["T3"].sum() > 500 and not masks["T30"].any()
    assert detections["T3"].width_rad > 2.0 * DEG


def test_tags_in_a_panorama() -> None:
    """Unwrapped: a tag's bearing is that of its centre column."""
    cal = UnwrappedCalibration(720, 160)
    image = np.full((160, 720), 120, np.uint8)
    marker = cv2.aruco.generateImageMarker(
        cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50), 5, 48
    )
    image[50:98, 100:148] = marker  # centre column 124: u = 124 continuous
    found = TagExtractor(cal, [LandmarkSpec("T5", None, tag=5)], "4x4_50").extract(image)
    expected = float(cal.bearing_of_column(124.0))
    assert found["T5"].bearing_rad == pytest.approx(expected, abs=0.02 * DEG)


def test_bad_tag_catalogs_raise_one_line() -> None:
    with pytest.raises(LandmarkCatalogError, match="L1 have no tag: a catalog is either"):
        make_extractor(CAL, [LandmarkSpec("T1", None, tag=1), LandmarkSpec("L1", "red")])
    with pytest.raises(LandmarkCatalogError, match="unknown tag dictionary '9x9'"):
        make_extractor(CAL, _catalog(), tag_dictionary="9x9")
    with pytest.raises(LandmarkCatalogError, match="same tag"):
        make_extractor(CAL, [LandmarkSpec("A", None, tag=1), LandmarkSpec("B", None, tag=1)])


def test_session_catalog_with_tags() -> None:
    doc = {
        "schema_version": 1,
        "software_version": "0",
        "created_unix_ns": 1,
        "simulated": False,
        "camera": {"source": "x", "calibration": CAL.to_dict()},
        "landmarks": [{"name": "A", "tag": 1}, {"name": "B", "tag": 2}],
        "reference": ["A", "B"],
        "vision_error_deg": 3.0,
        "tag_dictionary": "apriltag_36h11",
    }
    session = session_from_doc(doc)
    assert [s.tag for s in session.landmarks] == [
        1,
        2,
    ] and session.tag_dictionary == "apriltag_36h11"
    assert session.landmarks[0].label == "tag-1"
    doc["landmarks"] = [{"name": "A", "tag": 1, "color": "red"}, {"name": "B", "tag": 2}]
    with pytest.raises(SchemaError, match="a fiducial \\('tag'\\) has no 'color' or 'bands'"):
        session_from_doc(doc)
