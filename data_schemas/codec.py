"""Encode, decode and validate JSON messages and documents against their schemas.

Validation errors are :class:`~data_schemas.errors.SchemaError` with one line naming the topic
(or document) and the field, e.g.
``/robot/movement: field 'phase': 'middle' is not one of ['start', 'end']``.
"""

from __future__ import annotations

import json
import math
import re
from functools import cache
from typing import TYPE_CHECKING, Any

from data_schemas.errors import BslamError, SchemaError
from data_schemas.quick_check import conforms
from data_schemas.registry import schema_dict, topic

if TYPE_CHECKING:
    import jsonschema

#: How deep a JSON document or message may nest (objects and arrays). Ours nest 5 deep at most;
#: Python's parser and the validators recurse, so a deeper document is refused before them.
MAX_JSON_DEPTH = 64
#: Digits of a number too long to print in an error message (10**308 has 309).
_LONG_NUMBER = re.compile(r"\d{25,}")


@cache
def _schema(schema_name: str) -> dict[str, Any]:
    return schema_dict(schema_name)


@cache
def _validator(schema_name: str) -> jsonschema.protocols.Validator:
    import jsonschema  # ~70 ms: only when a document may be invalid (data_schemas/quick_check.py)

    schema = _schema(schema_name)
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
    require_finite(doc, what or schema_name)
    if conforms(_schema(schema_name), doc) is not True:
        from jsonschema.exceptions import best_match

        error = best_match(_validator(schema_name).iter_errors(doc))
        if error is not None:
            field, message = _explain(error)
            message = _LONG_NUMBER.sub(lambda m: f"a {len(m[0])}-digit number", message)
            raise SchemaError(f"{what or schema_name}: field {field!r}: {message}")


def _explain(error: jsonschema.ValidationError) -> tuple[str, str]:
    """(field, message) of a validation error.

    For a ``oneOf`` of objects told apart by a ``const`` field (a calibration's ``model``),
    the best error of the branch the document's ``const`` picks (or the allowed values of
    that field), rather than whatever branch ``best_match`` happened to descend into.
    """
    from jsonschema.exceptions import best_match

    one_of: jsonschema.ValidationError = error
    while one_of.validator != "oneOf" and one_of.parent is not None:
        one_of = one_of.parent  # type: ignore[assignment]
    instance = one_of.instance
    branches = one_of.validator_value if isinstance(one_of.validator_value, list) else []
    if one_of.validator != "oneOf" or not isinstance(instance, dict):
        return _located(error)
    by_branch: dict[int, list[jsonschema.ValidationError]] = {}
    for sub in one_of.context or ():
        by_branch.setdefault(int(sub.schema_path[0]), []).append(sub)
    consts = [
        {
            key: sub["const"]
            for key, sub in branch.get("properties", {}).items()
            if isinstance(sub, dict) and "const" in sub
        }
        for branch in branches
    ]
    matching = [
        i for i, c in enumerate(consts) if c and all(instance.get(k) == v for k, v in c.items())
    ]
    if len(matching) == 1 and by_branch.get(matching[0]):
        return _located(best_match(by_branch[matching[0]]) or error)
    keys = {k for c in consts for k in c}
    if not matching and len(keys) == 1:
        key = keys.pop()
        allowed = [c[key] for c in consts if key in c]
        path = [*one_of.absolute_path, key]
        return _field(path), f"{instance.get(key)!r} is not one of {allowed}"
    return _located(error)


def _located(error: jsonschema.ValidationError) -> tuple[str, str]:
    """(field, message); a missing required property is named as the field itself."""
    required = error.validator_value
    if (
        error.validator == "required"
        and isinstance(error.instance, dict)
        and isinstance(required, list)
    ):
        missing = [k for k in required if k not in error.instance]
        if missing:
            return _field([*error.absolute_path, missing[0]]), "is missing"
    return _field(error.absolute_path), error.message


def require_finite(doc: Any, what: str, *, path: str = "") -> None:
    """Raise SchemaError naming the field if ``doc`` holds NaN or an infinity anywhere.

    JSON has no NaN or infinity, but Python's parser accepts ``NaN`` and ``Infinity`` and JSON
    Schema's ``number`` lets them through; a document a user wrote must not carry them.
    """
    if isinstance(doc, float):
        _require_finite_number(doc, what, path)
        return
    if isinstance(doc, dict):
        entries: Any = doc.items()
    elif isinstance(doc, list):
        entries = enumerate(doc)
    else:
        return
    for key, value in entries:
        # scalars are checked here: no path is built for the thousands of particle coordinates
        if isinstance(value, float):
            if not math.isfinite(value):
                _require_finite_number(value, what, f"{path}.{key}" if path else str(key))
        elif isinstance(value, dict | list):
            require_finite(value, what, path=f"{path}.{key}" if path else str(key))


def _require_finite_number(value: float, what: str, path: str) -> None:
    if not math.isfinite(value):
        raise SchemaError(
            f"{what}: field {path or '(top level)'!r}: must be a finite number, got {value}"
        )


def validate_message(topic_name: str, msg: dict[str, Any]) -> None:
    """Validate a message for a registered topic (raise SchemaError naming topic and field)."""
    validate(topic(topic_name).schema, msg, what=topic_name)


def encode(topic_name: str, msg: dict[str, Any], *, check: bool = True) -> bytes:
    """Serialise a message for ``topic_name`` to JSON bytes, validating it first if ``check``."""
    if check:
        validate_message(topic_name, msg)
    return json.dumps(msg, separators=(",", ":")).encode()


def loads(text: str | bytes, *, what: str, error: type[BslamError] = SchemaError) -> Any:
    """Parse a JSON document or message that came from outside (a file, a log).

    Raises ``error`` (one line naming ``what``) for text that is not JSON or nests deeper than
    :data:`MAX_JSON_DEPTH`; never RecursionError.
    """
    deep = f"{what}: nests deeper than {MAX_JSON_DEPTH} levels"
    try:
        doc = json.loads(text)
    except UnicodeDecodeError as exc:
        raise error(f"{what}: not UTF-8 text ({exc.reason})") from None
    except json.JSONDecodeError as exc:
        where = f"line {exc.lineno}, column {exc.colno}"
        raise error(f"{what}: not valid JSON ({where}: {exc.msg})") from None
    except RecursionError:
        raise error(deep) from None
    if _too_deep(doc):
        raise error(deep)
    return doc


def _too_deep(doc: Any) -> bool:
    """``doc`` nests more than MAX_JSON_DEPTH objects and arrays (walked without recursion)."""
    level = [doc]
    for _ in range(MAX_JSON_DEPTH):
        level = [
            v
            for x in level
            if isinstance(x, dict | list)
            for v in (x.values() if isinstance(x, dict) else x)
            if isinstance(v, dict | list)
        ]
        if not level:
            return False
    return True


def decode(topic_name: str, data: bytes, *, check: bool = False) -> dict[str, Any]:
    """Parse JSON message bytes of ``topic_name``; validate them too if ``check``."""
    msg = loads(data, what=topic_name)
    if not isinstance(msg, dict):
        raise SchemaError(f"{topic_name}: message is not a JSON object")
    if check:
        validate_message(topic_name, msg)
    return msg
