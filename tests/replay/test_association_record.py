"""The final map's association as sinks receive it: counts per class and status, the one line
that says it, and the terminal view printing that line."""

from __future__ import annotations

import io

from logfactory import session_doc

from data_schemas.session import session_from_doc
from pipeline.association.final import FinalDetection
from replay.records import AssociationRecord, MethodConfig, RunInfo
from replay.sinks.terminal import TerminalView


def _record() -> AssociationRecord:
    rows = [
        FinalDetection(0, 0, "blue", 0.1, "blue#1", "named"),
        FinalDetection(0, 0, "blue", 0.2, None, "contested"),
        FinalDetection(0, 1, "blue", 0.6, None, "in line", ("blue#1", "blue#3")),
        FinalDetection(0, 1, "blue", -0.4, "blue#2", "named"),
        FinalDetection(1, 0, "blue", 1.0, None, "not placed"),
        FinalDetection(1, 0, "magenta/yellow", 2.0, None, "unexplained"),
    ]
    return AssociationRecord(10, 20, rows)


def test_counts_and_line_per_class() -> None:
    record = _record()
    assert record.counts() == {
        "blue": {
            "detections": 5,
            "named": 2,
            "in line": 1,
            "contested": 1,
            "unexplained": 0,
            "not placed": 1,
        },
        "magenta/yellow": {
            "detections": 1,
            "named": 0,
            "in line": 0,
            "contested": 0,
            "unexplained": 1,
            "not placed": 0,
        },
    }
    assert record.text() == (
        "with the final map, blue: 2 of 5 detections named (1 in line, 1 contested, 1 not "
        "placed); "
        "magenta/yellow: 0 of 1 detections named (1 unexplained)"
    )


def test_the_terminal_view_prints_the_line_when_not_a_terminal() -> None:
    out = io.StringIO()
    view = TerminalView(out)
    view.start(RunInfo("run.mcap", session_from_doc(session_doc()), MethodConfig(), None))
    view.association(_record())
    assert out.getvalue() == f"run.mcap: {_record().text()}\n"


def test_a_run_without_keyframe_detections_says_so() -> None:
    record = AssociationRecord(0, 0, [])
    assert record.counts() == {}
    assert record.text() == "with the final map, no detections to associate"
