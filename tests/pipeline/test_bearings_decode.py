"""Frames from the log to BGR: lossless only, clear errors (real OpenCV encoders/decoders)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from data_schemas.errors import ImageError
from pipeline.bearings import decode_frame


@pytest.fixture
def image() -> np.ndarray:
    return np.random.default_rng(5).integers(0, 256, (12, 17, 3), dtype=np.uint8)


def test_png_round_trip_is_exact(image: np.ndarray) -> None:
    ok, png = cv2.imencode(".png", image)
    assert ok
    decoded = decode_frame(png.tobytes(), "png")
    assert decoded.dtype == np.uint8 and np.array_equal(decoded, image)


def test_bgr8_raw_with_and_without_row_padding(image: np.ndarray) -> None:
    h, w = image.shape[:2]
    assert np.array_equal(decode_frame(image.tobytes(), "bgr8", width=w, height=h), image)
    padded = np.zeros((h, 3 * w + 5), np.uint8)
    padded[:, : 3 * w] = image.reshape(h, -1)
    got = decode_frame(padded.tobytes(), "bgr8", width=w, height=h, step=3 * w + 5)
    assert np.array_equal(got, image)


@pytest.mark.parametrize("fmt", ["jpeg", "JPG", "webp"])
def test_lossy_encodings_are_refused(image: np.ndarray, fmt: str) -> None:
    ok, jpg = cv2.imencode(".jpg", image)
    assert ok
    with pytest.raises(ImageError, match="lossy"):
        decode_frame(jpg.tobytes(), fmt)


def test_jpeg_bytes_labelled_png_are_refused(image: np.ndarray) -> None:
    ok, jpg = cv2.imencode(".jpg", image)
    assert ok
    with pytest.raises(ImageError, match="not a PNG"):
        decode_frame(jpg.tobytes(), "png")


def test_truncated_png_is_refused(image: np.ndarray) -> None:
    ok, png = cv2.imencode(".png", image)
    assert ok
    with pytest.raises(ImageError, match="corrupt or truncated"):
        decode_frame(png.tobytes()[:40], "png")


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({}, "needs its width and height"),
        ({"width": 17, "height": 11}, "expected 561"),
        ({"width": 17, "height": 12, "step": 40}, "step 40"),
    ],
)
def test_bgr8_size_errors(image: np.ndarray, kwargs: dict[str, int], message: str) -> None:
    with pytest.raises(ImageError, match=message):
        decode_frame(image.tobytes(), "bgr8", **kwargs)


def test_unknown_encoding_is_refused(image: np.ndarray) -> None:
    with pytest.raises(ImageError, match="unknown frame encoding 'rgb16'"):
        decode_frame(image.tobytes(), "rgb16")
