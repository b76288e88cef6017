"""Lossless PNG encoding of BGR frames, fast enough for the recorder's frame rates.

A PNG is a signature, an ``IHDR`` chunk (size, 8-bit RGB), one ``IDAT`` chunk holding the zlib
stream of the filtered rows, and ``IEND``. The rows are filtered with numpy (``SUB``: each byte
minus the same channel of the pixel on its left, modulo 256) and compressed with ISA-L's deflate
(``isal``), which is several times faster than zlib at the same size on camera images. Levels:

====== ============================================== =============================
level  filter and compressor                          use
====== ============================================== =============================
0      no filter, zlib stored blocks (no compression)  fastest PNG, raw size
1..3   SUB, ISA-L deflate level 1..3                   default 1: about half the size
====== ============================================== =============================

(zlib's own levels are 2 to 20 times slower than ISA-L level 1 on camera frames and no
smaller: sensor noise, not the search effort, bounds the size.)

Measured figures are in ``docs/recording.md`` and ``tests/bench/test_bench_writer.py``.
"""

from __future__ import annotations

import struct
import zlib

import cv2
import numpy as np
from isal import isal_zlib
from numpy.typing import NDArray

from data_schemas.errors import ImageError

SIGNATURE = b"\x89PNG\r\n\x1a\n"
_FILTER_NONE, _FILTER_SUB = 0, 1
_COLOR_RGB = 2
#: Largest ``png_level``.
MAX_LEVEL = 3


def check_level(level: int) -> int:
    """Return ``level`` if it is a PNG level 0..3, else raise ValueError."""
    if not 0 <= level <= MAX_LEVEL:
        raise ValueError(f"PNG level must be 0..{MAX_LEVEL}, got {level}")
    return level


def check_bgr(image_bgr: NDArray[np.uint8]) -> None:
    """Raise ImageError unless ``image_bgr`` is a non-empty BGR uint8 ``(H, W, 3)`` frame."""
    if image_bgr.dtype != np.uint8 or image_bgr.ndim != 3 or image_bgr.shape[2] != 3:
        raise ImageError(
            f"frames must be BGR uint8 (H, W, 3), got {image_bgr.dtype} {image_bgr.shape}"
        )
    if image_bgr.size == 0:
        raise ImageError(f"cannot record an empty frame of shape {image_bgr.shape}")


def encode_png(image_bgr: NDArray[np.uint8], level: int) -> bytes:
    """PNG bytes (8-bit RGB, lossless) of a BGR uint8 ``(H, W, 3)`` image.

    Parameters
    ----------
    image_bgr : ndarray, uint8, shape (H, W, 3)
        The frame, OpenCV channel order.
    level : int
        0..3, see the module table.
    """
    check_level(level)
    check_bgr(image_bgr)
    height, width = image_bgr.shape[:2]
    rows = _filtered_rows(image_bgr, sub=level > 0).data.cast("B")
    stream = isal_zlib.compress(rows, level) if level else zlib.compress(rows, 0)
    header = struct.pack(">IIBBBBB", width, height, 8, _COLOR_RGB, 0, 0, 0)
    return b"".join([SIGNATURE, *_chunk(b"IHDR", header), *_chunk(b"IDAT", stream), *_IEND])


def _filtered_rows(image_bgr: NDArray[np.uint8], *, sub: bool) -> NDArray[np.uint8]:
    """The PNG scanlines: per row a filter-type byte, then the (filtered) RGB bytes."""
    height, width = image_bgr.shape[:2]
    rgb = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2RGB).reshape(height, 3 * width)
    rows = np.empty((height, 1 + 3 * width), np.uint8)
    if not sub:
        rows[:, 0] = _FILTER_NONE
        rows[:, 1:] = rgb
        return rows
    rows[:, 0] = _FILTER_SUB
    rows[:, 1:4] = rgb[:, :3]
    np.subtract(rgb[:, 3:], rgb[:, :-3], out=rows[:, 4:])  # uint8 wraps modulo 256, as PNG
    return rows


def _chunk(kind: bytes, data: bytes) -> tuple[bytes, bytes, bytes, bytes]:
    """A PNG chunk as parts: length, type, data, CRC-32 of type and data."""
    crc = isal_zlib.crc32(data, isal_zlib.crc32(kind))
    return struct.pack(">I", len(data)), kind, data, struct.pack(">I", crc)


_IEND = _chunk(b"IEND", b"")
