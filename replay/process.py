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
from replay.records import MethodConfig, Sink
from replay.sinks.summary import AssociationOutcome, RunSummary, SummarySink
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
) -> RunSummary:
    """Process one log; return its summary (the document: :meth:`RunSummary.to_json`).

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
    summary_sink = SummarySink(window)
    sinks: list[Sink] = [summary_sink, *extra_sinks]
    with contextlib.ExitStack() as stack:
        opened = entered(log, stack, skip_corrupt=skip_corrupt)
        if window:
            opened = windowed(opened, window)
        if out is not None:
            from replay.sinks.derived import DerivedLogSink  # the MCAP writer only when asked

            sinks.append(DerivedLogSink(stack.enter_context(guard.staged(out))))
        run_log(opened, method, sinks)
    result = summary_sink.summary
    if summary is not None:
        write_json(summary, result.to_json(), guard)
    return result


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


def result_line(summary: RunSummary) -> str:
    """One line about a processed log: movements used, landmarks mapped, error if known."""
    text = f"{summary.used}/{summary.movements} movements used"
    if summary.resected:
        text += f" ({summary.resected} placed by resection)"
    pair = ", ".join(summary.reference)  # fixed in FL, never "mapped"
    text += f", {summary.landmarks} landmarks mapped besides the reference pair {pair}"
    if summary.bearing_noise_deg is not None:
        text += f", bearing noise {summary.bearing_noise_deg:.2f} deg"
    if summary.mean_error_m is not None:
        text += f", mean error {100 * summary.mean_error_m:.1f} cm"
    if summary.association is not None:
        text += _association_text(summary.association)
    if summary.untrusted:
        text += f"; the map is NOT trustworthy: {'; '.join(summary.untrusted)}"
    return text


def _association_text(assoc: AssociationOutcome) -> str:
    """The result line's part on the landmarks that look alike."""
    named = ", ".join(
        f"{label} {assoc.names_given.get(label, 0)}/{n}" for label, n in assoc.catalog_count.items()
    )
    text = f"; alike landmarks named: {named}"
    if assoc.detections:
        share = 100 * assoc.detections_named / assoc.detections
        text += f", {share:.0f} % of {assoc.detections} detections"
    final = assoc.final
    if final is not None and final.detections:
        matched = final.placed_by_matching
        also = f", movement(s) {', '.join(map(str, matched))} placed by matching" if matched else ""
        text += f" ({100 * final.explained / final.detections:.0f} % with the final map{also})"
    if assoc.movements_with_unresolved:
        text += f" ({len(assoc.movements_with_unresolved)} movement(s) with ambiguities)"
    if final is not None and final.named_at_end:
        text += (
            f"; with the final map, {', '.join(final.named_at_end)} named where detections no "
            "name explained meet"
        )
    if final is not None and final.retracted:
        text += (
            f"; with the final map, {', '.join(final.retracted)} given anew where the "
            "detections no name explained point (under suspicion before)"
        )
    if final is not None and final.missing:
        text += (
            f"; with the final map, {', '.join(final.missing)}: detections no name explains "
            "(a landmark may be missing)"
        )
    if assoc.doubtful:
        text += (
            f"; doubtful: {', '.join(assoc.doubtful)} "
            "(seen too rarely where predicted, or bearings that scatter)"
        )
    if assoc.unconfirmed:
        text += (
            f"; unconfirmed: {', '.join(assoc.unconfirmed)} "
            "(seen too few times since named to tell)"
        )
    return text
