"""``bslam process`` as a library call: one log in, a summary (and optionally a derived log) out."""

from __future__ import annotations

import contextlib
import json
import os
import re
from typing import Any

from data_schemas.mcap.open import LogSource, MessageLog, entered, log_path
from data_schemas.mcap.processable import ProcessableLog
from data_schemas.mcap.window import LogWindow, WindowedLog, WindowError
from data_schemas.outputs import OutputGuard
from pipeline.slam import MovementStatus, Placement
from replay.records import MethodConfig, Sink
from replay.sinks.summary import SummarySink
from replay.stages import run_log

_FLAT_LIST = re.compile(r"\[\s+([^\[\]{}]*?)\s+\]")


def dumps(doc: dict[str, Any]) -> str:
    """Indented JSON with innermost lists (coordinates, bearing pairs) kept on one line."""
    return _FLAT_LIST.sub(
        lambda m: "[" + " ".join(m.group(1).split()) + "]", json.dumps(doc, indent=1)
    )


def write_json(
    path: str | os.PathLike[str], doc: dict[str, Any], guard: OutputGuard | None = None
) -> None:
    """Write a JSON document (indented, trailing newline) whole, through a temporary file."""
    (guard or OutputGuard(force=True)).write_text(path, dumps(doc) + "\n")


def process_log(
    log: LogSource,
    method: MethodConfig,
    *,
    out: str | os.PathLike[str] | None = None,
    summary: str | os.PathLike[str] | None = None,
    extra_sinks: tuple[Sink, ...] = (),
    force: bool = False,
    skip_corrupt: bool = False,
    window: LogWindow | None = None,
) -> dict[str, Any]:
    """Process one log; return its summary document.

    Parameters
    ----------
    log : path, ProcessableLog or FollowedLog
        A finished bearing-slam log (a path, or one already opened), or a log being followed.
    method : MethodConfig
        Prior, particle counts and seed.
    out : path, optional
        Write the derived log here.
    summary : path, optional
        Write the summary JSON here.
    extra_sinks : tuple of Sink
        More sinks fed by the same pass (e.g. a Rerun sink).
    force : bool
        Replace existing outputs (never the log itself).
    skip_corrupt : bool
        Process a corrupt log without its damaged chunks (warned about) instead of refusing it.
    window : LogWindow, optional
        Only this part of a finished log (``--from`` / ``--to``).

    Raises
    ------
    OutputError
        An output is the log (or a link to it), exists without ``force``, or cannot be written;
        checked before anything is read.
    WindowError
        ``window`` names a movement the log does not have, or ``log`` is being followed.
    """
    guard = OutputGuard([log_path(log)], force=force)
    for path, what in ((out, "derived log"), (summary, "summary")):
        if path is not None:
            guard.claim(path, what=what)
    summary_sink = SummarySink()
    sinks: list[Sink] = [summary_sink, *extra_sinks]
    with contextlib.ExitStack() as stack:
        opened = entered(log, stack, skip_corrupt=skip_corrupt)
        if window:
            opened = windowed(opened, window)
        if out is not None:
            from replay.sinks.derived import DerivedLogSink  # the MCAP writer only when asked

            sinks.append(DerivedLogSink(stack.enter_context(guard.staged(out))))
        run_log(opened, method, sinks)
    if window:
        summary_sink.document["window"] = {
            k: str(b) for k, b in (("from", window.start), ("to", window.end)) if b is not None
        }
    if summary is not None:
        write_json(summary, summary_sink.document, guard)
    return summary_sink.document


def windowed(log: MessageLog, window: LogWindow) -> WindowedLog:
    """``log`` cut to ``window``.

    Raises
    ------
    WindowError
        ``log`` is not a finished log opened whole, or ``window`` names a movement it lacks.
    """
    if isinstance(log, WindowedLog):
        log = log.log
    if not isinstance(log, ProcessableLog):
        raise WindowError(f"{log.name}: --from/--to take a finished log, not one being followed")
    return WindowedLog(log, window)


def result_line(doc: dict[str, Any]) -> str:
    """One line about a processed log: movements used, landmarks mapped, error if known."""
    moves = doc["movements"]
    used = sum(1 for m in moves if m["status"] == MovementStatus.OK)
    resected = sum(1 for m in moves if m.get("placement") == Placement.RESECTION)
    text = f"{used}/{len(moves)} movements used"
    if resected:
        text += f" ({resected} placed by resection)"
    pair = f"{doc['frame']['origin']}, {doc['frame']['x_axis']}"  # fixed in FL, never "mapped"
    text += f", {len(doc['landmarks'])} landmarks mapped besides the reference pair {pair}"
    if "bearing_noise_deg" in doc:
        text += f", bearing noise {doc['bearing_noise_deg']:.2f} deg"
    if "mean_error_m" in doc:
        text += f", mean error {100 * doc['mean_error_m']:.1f} cm"
    assoc = doc.get("association")
    if assoc:
        named = ", ".join(
            f"{label} {len(assoc['named'].get(label, []))}/{n}"
            for label, n in assoc["catalog_count"].items()
        )
        text += f"; alike landmarks named: {named}"
        counts = assoc.get("detections", {}).values()
        seen = sum(c["at_keyframes"] for c in counts)
        if seen:
            text += f", {100 * sum(c['named'] for c in counts) / seen:.0f} % of {seen} detections"
        final = assoc.get("final_map", {})
        if sum(c["detections"] for c in final.values()):
            share = sum(c["named"] + c["in line"] for c in final.values()) / sum(
                c["detections"] for c in final.values()
            )
            matched = assoc.get("placed_by_matching", [])
            also = (
                f", movement(s) {', '.join(map(str, matched))} placed by matching"
                if matched
                else ""
            )
            text += f" ({100 * share:.0f} % with the final map{also})"
        if assoc["movements_with_unresolved"]:
            text += f" ({len(assoc['movements_with_unresolved'])} movement(s) with ambiguities)"
        found = [n for c in final.values() for n in c.get("named_at_end", {})]
        if found:
            text += (
                f"; with the final map, {', '.join(found)} named where detections no name "
                "explained meet"
            )
        retracted = [n for c in final.values() for n in c.get("retracted", {})]
        if retracted:
            text += (
                f"; with the final map, {', '.join(retracted)} given anew where the "
                "detections no name explained point (under suspicion before)"
            )
        missing = [label for label, c in final.items() if "warning" in c]
        if missing:
            text += (
                f"; with the final map, {', '.join(missing)}: detections no name explains "
                "(a landmark may be missing)"
            )
        if assoc.get("doubtful"):
            text += (
                f"; doubtful: {', '.join(assoc['doubtful'])} "
                "(seen too rarely where predicted, or bearings that scatter)"
            )
        if assoc.get("unconfirmed"):
            names = ", ".join(assoc["unconfirmed"])
            text += f"; unconfirmed: {names} (seen too few times since named to tell)"
    trust = doc.get("trust")
    if trust is not None and not trust["trustworthy"]:
        text += f"; the map is NOT trustworthy: {'; '.join(trust['reasons'])}"
    return text
