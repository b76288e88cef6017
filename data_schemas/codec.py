"""Encode, decode and validate JSON messages and documents against their schemas.

Validation errors are :class:`~data_schemas.errors.SchemaError` with one line naming the topic
(or document) and the field, e.g.
``/robot/movement: field 'phase': 'middle' is not one of ['start', 'end']``.
"""

from __future__ import annotations

import json
from functools import cache
from typing import Any

import jsonschema
from jsonschema.exceptions import best_match

from data_schemas.errors import SchemaError
from data_schemas.registry import schema_dict, topic


@cache
def _validator(schema_name: str) -> jsonschema.protocols.Validator:
    schema = schema_dict(schema_name)
    cls = jsonschema.validators.validator_for(schema, default=jsonschema.Draft202012Validator)
    validator: jsonschema.protocols.Validator = cls(schema)
    return validator


def _field(path: Any) -> str:
    parts = [str(p) for p in path]
    return ".".join(parts) if parts else "(top level)"


def validate(schema_name: str, doc: Any, *, what: str | None = None) -> None:
    """Check ``doc`` against schema ``schema_name``.

    Parameters
    ----------
    schema_name : str
        e.g. ``"bslam.Scenario"``.
    doc : object
        Decoded JSON.
    what : str, optional
        What to call the document in the error (a topic or a file name); default the schema name.

    Raises
    ------
    SchemaError
        One line naming ``what`` and the offending field.
    """
    error = best_match(_validator(schema_name).iter_errors(doc))
    if error is not None:
        label = what or schema_name
        raise SchemaError(f"{label}: field {_field(error.absolute_path)!r}: {error.message}")


def validate_message(topic_name: str, msg: dict[str, Any]) -> None:
    """Validate a message for a registered topic (raise SchemaError naming topic and field)."""
    validate(topic(topic_name).schema, msg, what=topic_name)


def encode(topic_name: str, msg: dict[str, Any], *, check: bool = True) -> bytes:
    """Serialise a message for ``topic_name`` to JSON bytes, validating it first if ``check``."""
    if check:
        validate_message(topic_name, msg)
    return json.dumps(msg, separators=(",", ":")).encode()


def decode(topic_name: str, data: bytes, *, check: bool = False) -> dict[str, Any]:
    """Parse JSON message bytes of ``topic_name``; validate them too if ``check``."""
    try:
        msg = json.loads(data)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise SchemaError(f"{topic_name}: message is not valid JSON ({exc})") from None
    if not isinstance(msg, dict):
        raise SchemaError(f"{topic_name}: message is not a JSON object")
    if check:
        validate_message(topic_name, msg)
    return msg
