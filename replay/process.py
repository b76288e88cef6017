"""``bslam process`` as a library call: one log in, a summary (and optionally a derived log) out."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path
from typing import Any

from data_schemas.errors import LogError
from replay.logs import ProcessableLog
from replay.records import MethodConfig, Sink
from replay.sinks.summary import SummarySink
from replay.stages import run_log

_FLAT_LIST = re.compile(r"\[\s+([^\[\]{}]*?)\s+\]")


def dumps(doc: dict[str, Any]) -> str:
    """Indented JSON with innermost lists (coordinates, bearing pairs) kept on one line."""
    return _FLAT_LIST.sub(
        lambda m: "[" + " ".join(m.group(1).split()) + "]", json.dumps(doc, indent=1)
    )


def write_json(path: str | os.PathLike[str], doc: dict[str, Any]) -> None:
    """Write a JSON document (indented, trailing newline); one-line error if it cannot."""
    try:
        Path(path).write_text(dumps(doc) + "\n", encoding="utf-8")
    except OSError as exc:
        raise LogError(f"cannot write {os.fspath(path)}: {exc.strerror}") from None


def process_log(
    log: str | os.PathLike[str] | ProcessableLog,
    method: MethodConfig,
    *,
    out: str | os.PathLike[str] | None = None,
    summary: str | os.PathLike[str] | None = None,
    extra_sinks: tuple[Sink, ...] = (),
) -> dict[str, Any]:
    """Process one log; return its summary document.

    Parameters
    ----------
    log : path or ProcessableLog
        A finished bearing-slam log (a path, or one already opened).
    method : MethodConfig
        Prior, particle counts and seed.
    out : path, optional
        Write the derived log here.
    summary : path, optional
        Write the summary JSON here.
    extra_sinks : tuple of Sink
        More sinks fed by the same pass (e.g. a Rerun sink).
    """
    summary_sink = SummarySink()
    sinks: list[Sink] = [summary_sink, *extra_sinks]
    if out is not None:
        from replay.sinks.derived import DerivedLogSink  # the MCAP writer only when asked

        source = log.path if isinstance(log, ProcessableLog) else Path(log)
        if Path(out).resolve() == source.resolve():
            raise LogError(f"{log}: --out would overwrite the source log; choose another path")
        sinks.append(DerivedLogSink(out))
    run_log(log, method, sinks)
    if summary is not None:
        write_json(summary, summary_sink.document)
    return summary_sink.document


def result_line(doc: dict[str, Any]) -> str:
    """One line about a processed log: movements used, landmarks mapped, error if known."""
    moves = doc["movements"]
    used = sum(1 for m in moves if m["status"] == "ok")
    text = f"{used}/{len(moves)} movements used, {len(doc['landmarks'])} landmarks mapped"
    if "mean_error_m" in doc:
        text += f", mean error {100 * doc['mean_error_m']:.1f} cm"
    shared = doc.get("ambiguous_classes", {})
    if shared:
        names = ", ".join(f"{' '.join(v)} ({k})" for k, v in shared.items())
        text += f"; not mapped, alike with no association: {names}"
    return text
