"""Frames from the log (bytes) to BGR images; lossless encodings only."""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from data_schemas.errors import ImageError

_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
_LOSSY = ("jpeg", "jpg", "webp", "avif", "heic", "h264", "h265")


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
