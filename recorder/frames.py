"""Camera frames as ``/camera/panorama`` messages: lossless PNG or raw ``bgr8``.

The image bytes are returned as a bytes-like ``data`` field:
:class:`data_schemas.mcap.writer.LogWriter` base64-encodes it straight into the JSON record (the
Foxglove JSON form of ``bytes``), so the multi-megabyte base64 text is never built as a Python
string. Encoding trade-off:

* ``png`` (``foxglove.CompressedImage``): :func:`recorder.png.encode_png`; level 1 stores about
  half the raw size and costs most of the recorder's time per frame;
* ``bgr8`` (``foxglove.RawImage``): the pixels as they are; the fastest (no encoding at all),
  the size of PNG level 0 (twice that of level 1).

Both are lossless and both are displayed by Foxglove's Image panel.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from data_schemas.registry import ImageEncoding
from data_schemas.stamps import stamp_from_ns
from recorder.png import check_bgr, encode_png

FRAME_ID = "panorama"


def frame_message(
    image_bgr: NDArray[np.uint8], t_ns: int, *, encoding: ImageEncoding, png_level: int = 1
) -> dict[str, Any]:
    """The ``/camera/panorama`` message of one frame taken at ``t_ns``, for ``LogWriter``.

    Parameters
    ----------
    image_bgr : ndarray, uint8, shape (H, W, 3)
        The frame, BGR.
    t_ns : int
        Capture time, ns since the epoch (session clock).
    encoding : {"png", "bgr8"}
        ``foxglove.CompressedImage`` PNG or ``foxglove.RawImage`` bgr8; both lossless.
    png_level : int
        PNG level 0..3 (:mod:`recorder.png`; ignored for ``bgr8``).

    Returns
    -------
    dict
        The message with ``data`` as bytes-like (PNG bytes, or the C-contiguous pixel array).
    """
    stamp = stamp_from_ns(t_ns)
    if encoding == "png":
        png = encode_png(image_bgr, png_level)
        return {"timestamp": stamp, "frame_id": FRAME_ID, "format": "png", "data": png}
    check_bgr(image_bgr)
    height, width = image_bgr.shape[:2]
    return {
        "timestamp": stamp,
        "frame_id": FRAME_ID,
        "width": width,
        "height": height,
        "encoding": "bgr8",
        "step": 3 * width,
        "data": np.ascontiguousarray(image_bgr).data.cast("B"),
    }
