"""Camera frames as ``/camera/panorama`` messages: lossless PNG or raw ``bgr8``, base64 in JSON.

PNG speed/size trade-off (``png_level``), measured on one core of the development machine with
noisy synthetic panoramas (see ``tests/bench/test_bench_writer.py`` for the recorder figures):

====== ====================================== ============== ===============
level  zlib settings                          176x255        1920x960
====== ====================================== ============== ===============
0      stored, no filter                      0.1 ms, 1.0x   5 ms, 1.0x
1      level 1, SUB filter, Huffman only      0.9 ms, ~0.5x  42 ms, ~0.45x
2..9   that zlib level, adaptive filters      >= 2 ms        >= 90 ms
====== ====================================== ============== ===============

(size relative to the raw BGR bytes). Level 1 is the default: half the size at over 1,000
frames/s for the paper's 176x255 panoramas; use level 0 for large frames at video rate.
"""

from __future__ import annotations

import base64
from typing import Any, Literal

import cv2
import numpy as np
from numpy.typing import NDArray

from data_schemas.errors import ImageError
from data_schemas.stamps import stamp_from_ns

Encoding = Literal["png", "bgr8"]
FRAME_ID = "panorama"
#: Schema of ``/camera/panorama`` for each encoding.
IMAGE_SCHEMA: dict[str, str] = {"png": "foxglove.CompressedImage", "bgr8": "foxglove.RawImage"}


def png_params(level: int) -> list[int]:
    """``cv2.imencode`` parameters for ``png_level`` 0..9 (see module table)."""
    if not 0 <= level <= 9:
        raise ValueError(f"PNG level must be 0..9, got {level}")
    if level == 0:
        return [cv2.IMWRITE_PNG_COMPRESSION, 0, cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_NONE]
    if level == 1:
        return [
            cv2.IMWRITE_PNG_COMPRESSION,
            1,
            cv2.IMWRITE_PNG_FILTER,
            cv2.IMWRITE_PNG_FILTER_SUB,
            cv2.IMWRITE_PNG_STRATEGY,
            cv2.IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY,
        ]
    return [cv2.IMWRITE_PNG_COMPRESSION, level]


def encode_png(image_bgr: NDArray[np.uint8], params: list[int]) -> bytes:
    """PNG bytes of a BGR uint8 ``(H, W, 3)`` image (``params`` from :func:`png_params`)."""
    ok, buf = cv2.imencode(".png", image_bgr, params)
    if not ok:
        raise ImageError(f"PNG encoding failed for an image of shape {image_bgr.shape}")
    return buf.tobytes()


def frame_message(
    image_bgr: NDArray[np.uint8], t_ns: int, *, encoding: Encoding, params: list[int]
) -> dict[str, Any]:
    """The ``/camera/panorama`` message of one frame taken at ``t_ns``.

    Parameters
    ----------
    image_bgr : ndarray, uint8, shape (H, W, 3)
        The frame, BGR.
    t_ns : int
        Capture time, ns since the epoch (session clock).
    encoding : {"png", "bgr8"}
        ``foxglove.CompressedImage`` PNG or ``foxglove.RawImage`` bgr8; both lossless.
    params : list of int
        PNG parameters (ignored for ``bgr8``).
    """
    if image_bgr.dtype != np.uint8 or image_bgr.ndim != 3 or image_bgr.shape[2] != 3:
        raise ImageError(
            f"frames must be BGR uint8 (H, W, 3), got {image_bgr.dtype} {image_bgr.shape}"
        )
    stamp = stamp_from_ns(t_ns)
    if encoding == "png":
        data = base64.b64encode(encode_png(image_bgr, params)).decode("ascii")
        return {"timestamp": stamp, "frame_id": FRAME_ID, "format": "png", "data": data}
    height, width = image_bgr.shape[:2]
    return {
        "timestamp": stamp,
        "frame_id": FRAME_ID,
        "width": width,
        "height": height,
        "encoding": "bgr8",
        "step": 3 * width,
        "data": base64.b64encode(np.ascontiguousarray(image_bgr).tobytes()).decode("ascii"),
    }
