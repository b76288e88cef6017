"""The image-schema map (data_schemas.registry.IMAGE_SCHEMA) is the one list of frame encodings."""

from __future__ import annotations

from typing import get_args

import numpy as np
import pytest

from data_schemas.codec import validate
from data_schemas.errors import SchemaError
from data_schemas.registry import IMAGE_SCHEMA, ImageEncoding, schema_dict
from recorder.frames import frame_message


def test_encodings_schemas_and_session_enum_agree() -> None:
    assert get_args(ImageEncoding) == tuple(IMAGE_SCHEMA)
    camera = schema_dict("bslam.Session")["properties"]["camera"]["properties"]
    assert camera["encoding"]["enum"] == list(IMAGE_SCHEMA)


@pytest.mark.parametrize("encoding", list(IMAGE_SCHEMA))
def test_each_encodings_frame_is_valid_under_its_schema(encoding: ImageEncoding) -> None:
    image = np.zeros((4, 6, 3), np.uint8)
    msg = frame_message(image, 1_000, encoding=encoding)
    msg["data"] = "AAAA"  # the writer base64-encodes the bytes; the schema checks the text
    validate(IMAGE_SCHEMA[encoding], msg)
    other = next(s for e, s in IMAGE_SCHEMA.items() if e != encoding)
    with pytest.raises(SchemaError, match="field"):
        validate(other, msg)
