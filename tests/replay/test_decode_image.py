"""Frames are decoded as their channel's schema says (the image-schema map), not by their shape."""

from __future__ import annotations

import base64
from typing import Any

import numpy as np
import pytest

from data_schemas.errors import ImageError
from data_schemas.registry import IMAGE_SCHEMA, ImageEncoding
from recorder.frames import frame_message
from replay.stages import decode_image

IMAGE = np.arange(5 * 7 * 3, dtype=np.uint8).reshape(5, 7, 3)


def _logged(encoding: ImageEncoding) -> dict[str, Any]:
    """A frame message as a reader returns it: ``data`` base64 text."""
    msg = frame_message(IMAGE, 1_000, encoding=encoding)
    return {**msg, "data": base64.b64encode(bytes(msg["data"])).decode()}


@pytest.mark.parametrize("encoding", list(IMAGE_SCHEMA))
def test_each_schema_decodes_its_encoding(encoding: ImageEncoding) -> None:
    msg = _logged(encoding)
    image, png = decode_image(IMAGE_SCHEMA[encoding], msg)
    assert np.array_equal(image, IMAGE)
    assert (png is not None) == (encoding == "png")
    if png is not None:
        assert png == base64.b64decode(msg["data"])


def test_a_frame_under_the_other_schema_is_refused() -> None:
    # a RawImage claiming a PNG file, and a CompressedImage claiming raw pixels
    raw = {**_logged("bgr8"), "encoding": "png"}
    with pytest.raises(ImageError, match=r"foxglove\.RawImage frame cannot hold 'png'"):
        decode_image(IMAGE_SCHEMA["bgr8"], raw)
    png = {**_logged("png"), "format": "bgr8"}
    with pytest.raises(ImageError, match=r"foxglove\.CompressedImage frame cannot hold 'bgr8'"):
        decode_image(IMAGE_SCHEMA["png"], png)


def test_a_schema_outside_the_map_is_refused() -> None:
    with pytest.raises(ImageError, match=r"'foxglove\.Log' is not an image schema"):
        decode_image("foxglove.Log", _logged("png"))


def test_lossy_format_names_itself() -> None:
    with pytest.raises(ImageError, match="'jpeg' is lossy"):
        decode_image(IMAGE_SCHEMA["png"], {**_logged("png"), "format": "jpeg"})
