"""A log's messages as JSON documents, one per message (what ``bslam cat`` prints).

Fields that hold bytes (a frame's ``data``, a point cloud's: declared ``contentEncoding:
base64`` in the channel's schema) are replaced by a short note of their size unless asked for.
"""

from __future__ import annotations

import json
from collections.abc import Collection, Iterator
from functools import cache
from typing import Any

from data_schemas.errors import UnknownSchemaError
from data_schemas.mcap.processable import ProcessableLog
from data_schemas.mcap.window import LogWindow, WindowedLog
from data_schemas.registry import schema_dict


@cache
def bytes_fields(schema: str) -> tuple[str, ...]:
    """The top-level fields of ``schema`` that carry base64 bytes."""
    properties = schema_dict(schema).get("properties", {})
    return tuple(
        name for name, prop in properties.items() if prop.get("contentEncoding") == "base64"
    )


def _elided(msg: dict[str, Any], fields: tuple[str, ...]) -> dict[str, Any]:
    for name in fields:
        value = msg.get(name)
        if isinstance(value, str):
            msg[name] = f"<{len(value) * 3 // 4 - value[-2:].count('=')} bytes>"
    return msg


def log_documents(
    log: ProcessableLog,
    topics: Collection[str] | None = None,
    *,
    window: LogWindow | None = None,
    with_bytes: bool = False,
) -> Iterator[dict[str, Any]]:
    """``{"topic", "log_time_ns", "message"}`` for each message of ``topics``, in log-time order.

    Raises
    ------
    UnknownSchemaError
        A topic the log does not carry (the message lists the ones it does).
    WindowError
        ``window`` names a movement the log does not have.
    """
    missing = sorted(set(topics or ()) - set(log.topics))
    if missing:
        raise UnknownSchemaError(
            f"{log.name} has no topic {', '.join(missing)}; its topics: "
            + ", ".join(sorted(log.topics))
        )
    source = WindowedLog(log, window) if window else log
    for msg in source.messages(topics):
        doc = json.loads(msg.data)
        if not with_bytes:
            doc = _elided(doc, bytes_fields(msg.schema))
        yield {"topic": msg.topic, "log_time_ns": msg.log_time_ns, "message": doc}
