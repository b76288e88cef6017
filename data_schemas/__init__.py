"""Log format of bearing-slam: JSON schemas for every channel, the topic registry, codec.

The leaf package: everything else may import it; it imports none of the others.
"""

from data_schemas.codec import decode, encode, validate, validate_message
from data_schemas.errors import BslamError, SchemaError
from data_schemas.registry import (
    MESSAGE_ENCODING,
    SCHEMA_ENCODING,
    SESSION_METADATA_NAME,
    TOPICS,
    schema_dict,
    schema_json,
    topic,
)
from data_schemas.stamps import ns_from_stamp, stamp_from_ns

__all__ = [
    "MESSAGE_ENCODING",
    "SCHEMA_ENCODING",
    "SESSION_METADATA_NAME",
    "TOPICS",
    "BslamError",
    "SchemaError",
    "decode",
    "encode",
    "ns_from_stamp",
    "schema_dict",
    "schema_json",
    "stamp_from_ns",
    "topic",
    "validate",
    "validate_message",
]
