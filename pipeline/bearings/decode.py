"""Frames from the log (bytes) to BGR images; lossless encodings only.

PNG frames in the recorder's own layout (``recorder.png``: 8-bit RGB, not interlaced, rows
filtered NONE or SUB, only IHDR, IDAT and IEND chunks) are decoded here with ISA-L's inflate and
a numpy running sum, more than twice as fast as OpenCV and to the same pixels; any other PNG,
and any damaged one (chunk CRC, zlib stream, size), is left to OpenCV.
"""

from __future__ import annotations

import struct

import cv2
import numpy as np
from isal import isal_zlib
from numpy.typing import NDArray

from data_schemas.errors import ImageError

_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
_LOSSY = ("jpeg", "jpg", "webp", "avif", "heic", "h264", "h265")
#: A chunk's length and type; its data and a CRC-32 of type and data follow.
_CHUNK_HEAD = struct.Struct(">I4s")
#: IHDR: width, height, bit depth, colour type, compression, filter method, interlace.
_IHDR = struct.Struct(">IIBBBBB")
_RGB8_PLAIN = (8, 2, 0, 0, 0)
_FILTER_SUB = 1


def decode_frame(
    data: bytes,
    fmt: str,
    *,
    width: int | None = None,
    height: int | None = None,
    step: int | None = None,
) -> NDArray[np.uint8]:
    """Decode one logged frame to a BGR image.

    Parameters
    ----------
    data : bytes
        The frame's bytes (``foxglove.CompressedImage.data`` or ``foxglove.RawImage.data``,
        already base64-decoded).
    fmt : str
        ``"png"`` (CompressedImage ``format``) or ``"bgr8"`` (RawImage ``encoding``).
    width, height : int, optional
        Image size; required for ``"bgr8"``.
    step : int, optional
        Bytes per row for ``"bgr8"`` (default ``3 * width``; larger means row padding).

    Returns
    -------
    ndarray, (H, W, 3) uint8
        BGR pixels.

    Raises
    ------
    ImageError
        Lossy or unknown encoding, bytes that are not that encoding, or a size mismatch.
    """
    kind = fmt.lower()
    if kind == "png":
        if not data.startswith(_PNG_MAGIC):
            raise ImageError("frame says format 'png' but its bytes are not a PNG image")
        plain = _decode_plain_png(data)
        if plain is not None:
            return plain
        image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
        if image is None:
            raise ImageError("frame's PNG data is corrupt or truncated and cannot be decoded")
        return np.asarray(image, dtype=np.uint8)
    if kind == "bgr8":
        if width is None or height is None:
            raise ImageError("a 'bgr8' frame needs its width and height to be decoded")
        row = 3 * width if step is None else step
        if row < 3 * width or len(data) != row * height:
            raise ImageError(
                f"'bgr8' frame has {len(data)} bytes, expected {row * height} "
                f"for {width}x{height} with step {row}"
            )
        rows = np.frombuffer(data, np.uint8).reshape(height, row)
        return rows[:, : 3 * width].reshape(height, width, 3)
    if kind in _LOSSY:
        raise ImageError(
            f"frame encoding {fmt!r} is lossy; bearings need lossless frames (png or bgr8)"
        )
    raise ImageError(f"unknown frame encoding {fmt!r}; expected 'png' or 'bgr8'")


def _decode_plain_png(data: bytes) -> NDArray[np.uint8] | None:
    """BGR pixels of a PNG in the recorder's layout, or None for any other (or damaged) PNG."""
    chunks = _chunks(data)  # the last is IEND
    if chunks is None or chunks[0][0] != b"IHDR" or len(chunks[0][1]) != _IHDR.size:
        return None
    if any(kind != b"IDAT" for kind, _ in chunks[1:-1]):
        return None  # palette, transparency, gamma, EXIF...: OpenCV's business
    width, height, *layout = _IHDR.unpack(chunks[0][1])
    if tuple(layout) != _RGB8_PLAIN or not width or not height:
        return None
    try:
        raw = isal_zlib.decompress(b"".join(body for kind, body in chunks if kind == b"IDAT"))
    except isal_zlib.error:  # type: ignore[misc]  # (the stub declares an instance)
        return None
    if len(raw) != height * (1 + 3 * width):
        return None
    rows = np.frombuffer(raw, np.uint8).reshape(height, 1 + 3 * width)
    if np.any(rows[:, 0] > _FILTER_SUB):
        return None  # UP, AVERAGE, PAETH rows
    sub = rows[:, 0] == _FILTER_SUB
    rgb = rows[:, 1:]
    if sub.all():
        rgb = _undo_sub(rgb)
    elif sub.any():
        rgb = rgb.copy()
        rgb[sub] = _undo_sub(rgb[sub])
    pixels = rgb.reshape(height, width, 3)
    return np.asarray(cv2.cvtColor(pixels, cv2.COLOR_RGB2BGR), dtype=np.uint8)


def _undo_sub(rows: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """RGB bytes (n, 3 W) of rows filtered SUB: each byte plus the same channel's byte on its
    left, as already restored (a running sum per channel, modulo 256).

    The running sum by doubling: after the pass with shift ``k`` every byte holds the sum of
    the ``k / 3`` pixels ending at it, so ``log2(W)`` whole-image additions, done on the
    transposed rows where each shift is one contiguous block (a per-row ``cumsum`` is a scalar
    loop, 4-5x slower).
    """
    done = np.asarray(cv2.transpose(rows), np.uint8)  # (3 W, n): byte columns as rows
    spare = np.empty_like(done)
    shift = 3
    while shift < done.shape[0]:
        np.add(done[shift:], done[:-shift], out=spare[shift:])
        spare[:shift] = done[:shift]
        done, spare = spare, done
        shift *= 2
    return np.asarray(cv2.transpose(done), np.uint8)


def _chunks(data: bytes) -> list[tuple[bytes, memoryview]] | None:
    """(type, data) of each chunk up to IEND, or None if one is cut short or fails its CRC."""
    view = memoryview(data)
    pos = len(_PNG_MAGIC)
    found: list[tuple[bytes, memoryview]] = []
    while not found or found[-1][0] != b"IEND":
        if pos + _CHUNK_HEAD.size > len(data):
            return None
        length, kind = _CHUNK_HEAD.unpack_from(data, pos)
        end = pos + _CHUNK_HEAD.size + length
        crc = view[end : end + 4]
        if len(crc) != 4 or isal_zlib.crc32(view[pos + 4 : end]) != int.from_bytes(crc, "big"):
            return None
        found.append((kind, view[pos + _CHUNK_HEAD.size : end]))
        pos = end + 4
    return found
