"""A cheap check of decoded messages on read: required fields, JSON types, enums.

Full JSON Schema validation of every message would cost more than decoding it, so a log is
read with this shallow check instead: it is compiled once per schema from the schema itself
(``required``, ``type``, ``enum``/``const`` and nested objects) and walks only the fields the
schema names. What it finds is one :class:`~data_schemas.errors.SchemaError` line naming the
topic, the log time and the field, e.g.
``/robot/movement at log time 1700000000.100000000 s: field 'phase' is missing``.
Integers are held to their schema's ``minimum`` and ``maximum`` and always to 64 bits (a
movement index of 10**30 never reaches GTSAM); other bounds (string lengths, array sizes,
numbers) are left to full validation on write.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache
from typing import Any

from data_schemas.errors import SchemaError, UnknownSchemaError
from data_schemas.registry import schema_dict

#: A compiled check: returns ``(field path, problem)`` or None.
Check = Callable[[Any], tuple[str, str] | None]

_TYPES: dict[str, Callable[[Any], bool]] = {
    "object": lambda v: isinstance(v, dict),
    "array": lambda v: isinstance(v, list),
    "string": lambda v: isinstance(v, str),
    "boolean": lambda v: isinstance(v, bool),
    "integer": lambda v: isinstance(v, int) and not isinstance(v, bool),
    "number": lambda v: isinstance(v, int | float) and not isinstance(v, bool),
    "null": lambda v: v is None,
}


_ARTICLE = {
    "object": "an object",
    "array": "an array",
    "string": "a string",
    "boolean": "a boolean",
    "integer": "an integer",
    "number": "a number",
    "null": "null",
}


#: Integers a message may hold without a tighter bound in its schema (signed 64 bits).
INT64 = (-(2**63), 2**63 - 1)


def brief(value: int) -> str:
    """An integer for an error message: digits, or how many there are (a 309-digit number)."""
    text = str(value)
    return text if len(text) <= 24 else f"a {len(text.lstrip('-'))}-digit number"


def _integer_range(schema: dict[str, Any], path: str) -> Check:
    low = max(schema.get("minimum", INT64[0]), INT64[0])
    high = min(schema.get("maximum", INT64[1]), INT64[1])

    def check_range(v: Any) -> tuple[str, str] | None:
        if not isinstance(v, int) or low <= v <= high:
            return None
        return path, f"should be in [{low}, {high}], got {brief(v)}"

    return check_range


def _join(prefix: str, key: str) -> str:
    return f"{prefix}.{key}" if prefix else key


def _compile(schema: dict[str, Any], path: str) -> Check | None:
    """A check of one value against ``schema`` (None when there is nothing cheap to check)."""
    checks: list[Check] = []
    kind = schema.get("type")
    if isinstance(kind, str) and kind in _TYPES:
        is_kind = _TYPES[kind]

        def check_type(v: Any) -> tuple[str, str] | None:
            return (
                None
                if is_kind(v)
                else (path, f"should be {_ARTICLE[kind]}, got {type(v).__name__}")
            )

        checks.append(check_type)
    if kind == "integer":
        checks.append(_integer_range(schema, path))
    choices = schema.get("enum", [schema["const"]] if "const" in schema else None)
    if choices is not None:

        def check_enum(v: Any) -> tuple[str, str] | None:
            return None if v in choices else (path, f"should be one of {choices}, got {v!r}")

        checks.append(check_enum)
    required = tuple(schema.get("required", ()))
    props = {
        key: check
        for key, sub in schema.get("properties", {}).items()
        if isinstance(sub, dict) and (check := _compile(sub, _join(path, key))) is not None
    }
    if required or props:

        def check_object(v: Any) -> tuple[str, str] | None:
            if not isinstance(v, dict):
                return None  # the type check reports it, if the schema asks for an object
            for key in required:
                if key not in v:
                    return _join(path, key), "is missing"
            for key, check in props.items():
                if key in v and (found := check(v[key])) is not None:
                    return found
            return None

        checks.append(check_object)
    items = schema.get("items")
    item_check = _compile(items, f"{path}[]") if isinstance(items, dict) else None
    if item_check is not None:

        def check_items(v: Any) -> tuple[str, str] | None:
            if isinstance(v, list):
                for item in v:
                    if (found := item_check(item)) is not None:
                        return found
            return None

        checks.append(check_items)
    if not checks:
        return None
    if len(checks) == 1:
        return checks[0]

    def check_all(v: Any) -> tuple[str, str] | None:
        for check in checks:
            if (found := check(v)) is not None:
                return found
        return None

    return check_all


@cache
def _check_of(schema_name: str) -> Check:
    try:
        schema = schema_dict(schema_name)
    except UnknownSchemaError:  # a channel this version does not know: nothing to check
        return lambda v: None
    return _compile(schema, "") or (lambda v: None)


def check_shape(schema_name: str, msg: Any, *, topic: str, log_time_ns: int) -> None:
    """Raise SchemaError if ``msg`` lacks a required field or has one of the wrong JSON type.

    Parameters
    ----------
    schema_name : str
        The channel's schema, e.g. ``"bslam.Movement"``.
    msg : object
        The decoded message.
    topic : str
        Channel topic (for the message).
    log_time_ns : int
        The message's log time, ns since the epoch (for the message).
    """
    found = _check_of(schema_name)(msg)
    if found is not None:
        field, problem = found
        raise SchemaError(
            f"{topic} at log time {log_time_ns / 1e9:.9f} s: field {field or '(top level)'!r} "
            f"{problem}; the log does not match schema {schema_name}"
        )
