"""Reading an imported log back with the mcap library itself (no code of ours)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from mcap.reader import make_reader


def read_back(path: Path) -> tuple[dict[str, Any], list[tuple[str, int, int, dict[str, Any]]]]:
    """The session document and every message as (topic, log_time, publish_time, document)."""
    with path.open("rb") as f:
        reader = make_reader(f)
        session = next(m for m in reader.iter_metadata() if m.name == "bslam.session")
        messages = [
            (ch.topic, m.log_time, m.publish_time, json.loads(m.data))
            for _, ch, m in reader.iter_messages(log_time_order=False)
        ]
    return json.loads(session.metadata["json"]), messages


def on(messages: list[tuple[str, int, int, dict[str, Any]]], topic: str) -> list[dict[str, Any]]:
    """The documents of one topic, in file order."""
    return [doc for t, _, _, doc in messages if t == topic]
