"""A quick, conservative check of a JSON document against one of our schemas, without jsonschema.

:func:`conforms` answers ``True`` only when the document is valid under the keywords it knows (the
subset of JSON Schema 2020-12 our schema files use), ``False`` only when one of them fails, and
``None`` when it meets anything it does not know (another keyword, an unusual value type): the
caller then asks jsonschema, which also writes the error message. Its purpose is to spare a
command the import of jsonschema (about 70 ms) when every document it checks is valid.
``tests/data_schemas/test_quick_check.py`` holds it to jsonschema's verdict on generated documents.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

#: Keywords that do not constrain a document (annotations).
_ANNOTATIONS = frozenset(
    {"$schema", "$id", "$comment", "title", "description", "contentEncoding", "contentMediaType"}
    | {"default", "examples"}
)

#: Keywords :func:`conforms` checks itself.
_CHECKED = frozenset(
    {"type", "properties", "required", "additionalProperties", "items", "minItems", "maxItems"}
    | {"enum", "const", "minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"}
    | {"minLength", "oneOf"}
)

_JSON_TYPES = (dict, list, str, int, float, bool, type(None))


def _is_number(value: Any) -> bool:
    return type(value) is int or type(value) is float


def _has_type(value: Any, name: str) -> bool | None:
    """Whether ``value`` (a plain JSON value) is of JSON Schema type ``name``."""
    if name == "object":
        return type(value) is dict
    if name == "array":
        return type(value) is list
    if name == "string":
        return type(value) is str
    if name == "number":
        return _is_number(value)
    if name == "integer":
        return type(value) is int or (type(value) is float and value.is_integer())
    if name == "boolean":
        return type(value) is bool
    if name == "null":
        return value is None
    return None


def _equal(value: Any, wanted: Any) -> bool | None:
    """JSON equality where it is plain (strings, null, integers); ``None`` otherwise."""
    for v in (value, wanted):
        if type(v) not in (str, int, type(None)):
            return None
    return type(value) is type(wanted) and value == wanted


def _all(results: Any) -> bool | None:
    """``False`` if any is ``False``, else ``None`` if any is ``None``, else ``True``."""
    unknown = False
    for result in results:
        if result is False:
            return False
        if result is None:
            unknown = True
    return None if unknown else True


def conforms(schema: Mapping[str, Any] | bool, doc: Any) -> bool | None:
    """Whether ``doc`` is valid under ``schema``, if that can be told without jsonschema.

    Parameters
    ----------
    schema : mapping or bool
        A JSON Schema with every ``$ref`` inlined (``registry.schema_dict``).
    doc : object
        Decoded JSON (dicts, lists, str, int, float, bool, None).

    Returns
    -------
    bool or None
        ``True`` valid, ``False`` invalid, ``None`` not known here (ask jsonschema).
    """
    if type(schema) is bool:
        return schema
    if not isinstance(schema, Mapping) or type(doc) not in _JSON_TYPES:
        return None
    if any(key not in _CHECKED and key not in _ANNOTATIONS for key in schema):
        return None
    return _all(_keyword(key, value, schema, doc) for key, value in schema.items())


def _keyword(key: str, value: Any, schema: Mapping[str, Any], doc: Any) -> bool | None:
    """One keyword's verdict on ``doc`` (``True`` where it does not apply)."""
    if key in _ANNOTATIONS:
        return True
    if key == "type":
        names = value if type(value) is list else [value]
        verdicts = [_has_type(doc, name) for name in names]
        return True if True in verdicts else (None if None in verdicts else False)
    if key in ("enum", "const"):
        options = value if key == "enum" else [value]
        if type(options) is not list:
            return None
        verdicts = [_equal(doc, option) for option in options]
        return True if True in verdicts else (None if None in verdicts else False)
    if key == "oneOf":
        if type(value) is not list:
            return None
        verdicts = [conforms(branch, doc) for branch in value]
        return None if None in verdicts else verdicts.count(True) == 1
    if _is_number(doc) and key in ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"):
        if not _is_number(value):
            return None
        if key == "minimum":
            return not doc < value
        if key == "maximum":
            return not doc > value
        if key == "exclusiveMinimum":
            return not doc <= value
        return not doc >= value
    if type(doc) is str and key == "minLength":
        return len(doc) >= value if type(value) is int else None
    if type(doc) is list:
        return _array_keyword(key, value, doc)
    if type(doc) is dict:
        return _object_keyword(key, value, schema, doc)
    return True  # the keyword applies to another type


def _array_keyword(key: str, value: Any, doc: list[Any]) -> bool | None:
    if key in ("minItems", "maxItems"):
        if type(value) is not int:
            return None
        return len(doc) >= value if key == "minItems" else len(doc) <= value
    if key == "items":
        if value == {"type": "number"}:  # particle coordinates: thousands per message
            return all(type(v) is float or type(v) is int for v in doc)
        return _all(conforms(value, item) for item in doc)
    return True


def _object_keyword(
    key: str, value: Any, schema: Mapping[str, Any], doc: dict[str, Any]
) -> bool | None:
    if key == "required":
        return all(name in doc for name in value) if type(value) is list else None
    if key == "properties":
        if not isinstance(value, Mapping):
            return None
        return _all(conforms(value[name], doc[name]) for name in value if name in doc)
    if key == "additionalProperties":
        known = schema.get("properties", {})
        return _all(conforms(value, item) for name, item in doc.items() if name not in known)
    return True
