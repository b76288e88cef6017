"""Frames from the log to BGR: lossless only, clear errors (real OpenCV encoders/decoders)."""

from __future__ import annotations

import itertools
import struct
import zlib
from typing import Any

import cv2
import numpy as np
import pytest

from data_schemas.errors import ImageError
from pipeline.bearings import decode_frame
from recorder.png import encode_png


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


# ---------------------------------------------------------------- the recorder's PNG layout
def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def _png(
    rows: np.ndarray,
    width: int,
    height: int,
    *,
    idat_parts: int = 1,
    layout: tuple[int, ...] = (8, 2, 0, 0, 0),
    extra: bytes = b"",
) -> bytes:
    """A PNG of given filtered scanlines: its zlib stream split over IDAT chunks, ``extra``
    chunks before them, IHDR ``layout`` (bit depth, colour type, compression, filter,
    interlace)."""
    stream = zlib.compress(rows.tobytes(), 6)
    cuts = np.linspace(0, len(stream), idat_parts + 1).astype(int)
    idat = b"".join(_chunk(b"IDAT", stream[a:b]) for a, b in itertools.pairwise(cuts))
    header = _chunk(b"IHDR", struct.pack(">II", width, height) + bytes(layout))
    return b"\x89PNG\r\n\x1a\n" + header + extra + idat + _chunk(b"IEND", b"")


def _scanlines(image_bgr: np.ndarray, filters: np.ndarray) -> np.ndarray:
    """Rows filtered NONE (0) or SUB (1) as chosen per row."""
    height, width = image_bgr.shape[:2]
    rgb = image_bgr[:, :, ::-1].reshape(height, 3 * width)
    rows = np.empty((height, 1 + 3 * width), np.uint8)
    rows[:, 0] = filters
    rows[:, 1:] = rgb
    sub = filters == 1
    rows[sub, 4:] = rgb[sub, 3:] - rgb[sub, :-3]  # uint8 wraps modulo 256
    return rows


@pytest.fixture
def no_opencv_decoder(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Count OpenCV's PNG decodes (and still do them)."""
    calls: list[int] = []
    real = cv2.imdecode

    def counted(buf: np.ndarray, flags: int) -> np.ndarray | None:
        calls.append(1)
        return real(buf, flags)

    monkeypatch.setattr("pipeline.bearings.decode.cv2.imdecode", counted)
    return calls


@pytest.mark.parametrize("level", [0, 1, 2, 3])
@pytest.mark.parametrize("shape", [(1, 1), (4, 2), (12, 17), (176, 255), (3, 700)])
def test_recorder_pngs_decode_without_opencv_to_its_pixels(
    level: int, shape: tuple[int, int], no_opencv_decoder: list[int]
) -> None:
    image = np.random.default_rng(level).integers(0, 256, (*shape, 3), dtype=np.uint8)
    png = encode_png(image, level)
    decoded = decode_frame(png, "png")
    assert no_opencv_decoder == []
    assert decoded.dtype == np.uint8 and decoded.flags.c_contiguous
    assert np.array_equal(decoded, image)
    assert np.array_equal(decoded, cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR))


def test_mixed_none_and_sub_rows_over_many_idat_chunks(no_opencv_decoder: list[int]) -> None:
    rng = np.random.default_rng(9)
    image = rng.integers(0, 256, (23, 31, 3), dtype=np.uint8)
    png = _png(_scanlines(image, rng.integers(0, 2, 23).astype(np.uint8)), 31, 23, idat_parts=4)
    assert np.array_equal(decode_frame(png, "png"), image)
    assert no_opencv_decoder == []


def _png_filter(name: str) -> Any:
    """``imencode`` parameters for one PNG row filter (OpenCV >= 4.12; skipped before)."""
    if not hasattr(cv2, "IMWRITE_PNG_FILTER"):
        return pytest.param("bgr", [], marks=pytest.mark.skip(reason="OpenCV < 4.12"))
    return ("bgr", [cv2.IMWRITE_PNG_FILTER, getattr(cv2, f"IMWRITE_PNG_FILTER_{name}")])


@pytest.mark.parametrize(
    ("encoded", "params"),
    [
        _png_filter("PAETH"),
        _png_filter("UP"),
        _png_filter("AVG"),
        ("gray", []),
        ("bgra", []),
        ("16-bit", []),
    ],
)
def test_other_pngs_are_left_to_opencv(
    image: np.ndarray, encoded: str, params: list[int], no_opencv_decoder: list[int]
) -> None:
    pixels = {
        "bgr": image,
        "gray": cv2.cvtColor(image, cv2.COLOR_BGR2GRAY),
        "bgra": cv2.cvtColor(image, cv2.COLOR_BGR2BGRA),
        "16-bit": image.astype(np.uint16) * 257,
    }[encoded]
    ok, buf = cv2.imencode(".png", pixels, params)
    assert ok
    png = buf.tobytes()
    decoded = decode_frame(png, "png")
    assert len(no_opencv_decoder) == 1
    assert np.array_equal(decoded, cv2.imdecode(buf, cv2.IMREAD_COLOR))
    if encoded != "gray":
        assert np.array_equal(decoded, image)


def test_extra_chunks_and_rows_are_left_to_opencv(
    image: np.ndarray, no_opencv_decoder: list[int]
) -> None:
    h, w = image.shape[:2]
    rows = _scanlines(image, np.ones(h, np.uint8))
    text = _png(rows, w, h, extra=_chunk(b"tEXt", b"Comment\x00hello"))
    assert np.array_equal(decode_frame(text, "png"), image)
    one_more = _png(np.vstack([rows, rows[:1]]), w, h)  # a row more than IHDR says
    expected = cv2.imdecode(np.frombuffer(one_more, np.uint8), cv2.IMREAD_COLOR)
    assert np.array_equal(decode_frame(one_more, "png"), expected)
    assert len(no_opencv_decoder) == 3


def test_unknown_compression_method_is_refused(image: np.ndarray) -> None:
    h, w = image.shape[:2]
    png = _png(_scanlines(image, np.ones(h, np.uint8)), w, h, layout=(8, 2, 1, 0, 0))
    with pytest.raises(ImageError, match="corrupt or truncated"):
        decode_frame(png, "png")


@pytest.mark.parametrize("damage", ["idat data", "idat crc", "zlib data", "cut short", "no iend"])
def test_damaged_recorder_png_is_refused(image: np.ndarray, damage: str) -> None:
    png = bytearray(encode_png(image, 1))
    idat = png.index(b"IDAT")
    length = struct.unpack(">I", png[idat - 4 : idat])[0]
    crc_at = idat + 4 + length
    if damage == "idat data":
        png[idat + 10] ^= 0xFF  # data changed, CRC not
    elif damage == "idat crc":
        png[crc_at] ^= 0xFF  # data intact, CRC wrong
    elif damage == "zlib data":
        png[idat + 10] ^= 0xFF
        png[crc_at : crc_at + 4] = struct.pack(">I", zlib.crc32(png[idat:crc_at]))
    elif damage == "cut short":
        del png[len(png) // 2 :]
    else:
        del png[-12:]
    with pytest.raises(ImageError, match="corrupt or truncated"):
        decode_frame(bytes(png), "png")
