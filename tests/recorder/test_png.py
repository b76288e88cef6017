"""recorder.png: lossless PNG of BGR frames, read back by OpenCV and by Pillow."""

from __future__ import annotations

import io
import struct
import zlib

import cv2
import numpy as np
import pytest
from PIL import Image

from data_schemas.errors import ImageError
from recorder.png import MAX_LEVEL, SIGNATURE, encode_png


def _images() -> list[np.ndarray]:
    rng = np.random.default_rng(4)
    smooth = np.zeros((40, 70, 3), np.uint8)
    smooth[..., 0] = np.arange(70) * 3
    smooth[..., 2] = np.arange(40)[:, None] * 6
    return [
        rng.integers(0, 256, (17, 33, 3), dtype=np.uint8),  # noise: SUB wraps modulo 256
        smooth,
        np.full((5, 9, 3), (10, 200, 30), np.uint8),
        rng.integers(0, 256, (1, 1, 3), dtype=np.uint8),
        rng.integers(0, 256, (1, 50, 3), dtype=np.uint8),
        rng.integers(0, 256, (50, 1, 3), dtype=np.uint8),
        rng.integers(0, 256, (30, 40, 3), dtype=np.uint8)[::2, ::3],  # not contiguous
    ]


@pytest.mark.parametrize("level", range(MAX_LEVEL + 1))
def test_lossless_for_opencv_and_pillow(level: int) -> None:
    for image in _images():
        png = encode_png(image, level)
        assert png.startswith(SIGNATURE)
        decoded = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_UNCHANGED)
        assert decoded.shape == image.shape and np.array_equal(decoded, image)
        with Image.open(io.BytesIO(png)) as pil:
            pil.load()  # Pillow checks every chunk CRC
            assert pil.mode == "RGB"
            assert np.array_equal(np.asarray(pil), image[:, :, ::-1])


def test_chunks_and_compression() -> None:
    image = np.random.default_rng(0).integers(100, 104, (60, 80, 3), dtype=np.uint8)
    stored, fast = encode_png(image, 0), encode_png(image, 1)
    kinds = []
    pos = len(SIGNATURE)
    while pos < len(stored):
        (length,) = struct.unpack_from(">I", stored, pos)
        kind = stored[pos + 4 : pos + 8]
        data = stored[pos + 8 : pos + 8 + length]
        (crc,) = struct.unpack_from(">I", stored, pos + 8 + length)
        assert crc == zlib.crc32(kind + data)
        kinds.append(kind)
        if kind == b"IDAT":
            rows = zlib.decompress(data)
            assert len(rows) == 60 * (1 + 80 * 3)
            assert rows[:: 1 + 80 * 3] == bytes(60)  # level 0: filter type 0 on every row
        pos += 12 + length
    assert kinds == [b"IHDR", b"IDAT", b"IEND"]
    assert len(stored) > image.nbytes > 2 * len(fast)  # 2-bit noise compresses well


def test_bad_input() -> None:
    image = np.zeros((4, 4, 3), np.uint8)
    with pytest.raises(ValueError, match=r"PNG level must be 0\.\.3, got 4"):
        encode_png(image, 4)
    with pytest.raises(ImageError, match=r"BGR uint8 \(H, W, 3\), got uint16"):
        encode_png(image.astype(np.uint16), 1)
    with pytest.raises(ImageError, match=r"got uint8 \(4, 4\)"):
        encode_png(image[:, :, 0], 1)
    with pytest.raises(ImageError, match="empty frame"):
        encode_png(image[:0], 1)
