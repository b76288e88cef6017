"""The trust verdict of a summary (replay/trust.py) and the result line that says it."""

from __future__ import annotations

from typing import Any

from replay.process import result_line
from replay.trust import trust_entry, trust_reasons


def _doc(statuses: list[str], association: dict[str, Any] | None = None) -> dict[str, Any]:
    doc: dict[str, Any] = {
        "frame": {"origin": "L1", "x_axis": "L2"},
        "movements": [{"index": k, "status": s} for k, s in enumerate(statuses)],
        "landmarks": {"L3": {"mean": [0.5, 0.5]}},
    }
    if association is not None:
        doc["association"] = association
    return doc


def test_a_map_nothing_doubts_is_trustworthy() -> None:
    doc = _doc(["ok"] * 9 + ["skipped: too few bearings of mapped landmarks"])
    assert trust_reasons(doc) == []
    assert trust_entry(doc) == {"trustworthy": True}
    doc["trust"] = trust_entry(doc)
    assert "NOT trustworthy" not in result_line(doc)


def test_a_map_collapsed_onto_the_robot_is_not_trustworthy() -> None:
    doc = _doc(["ok"] * 3)
    doc["landmarks"] = {"L3": {"mean": [0.0, 0.0]}, "L4": {"mean": [0.3, 0.5]}}
    doc["movements"][2]["observation_points"] = {"o1": [0.3, 0.494], "o2": [0.8, 0.8]}
    assert trust_reasons(doc) == []  # 0.006 FL from a keyframe: near it, not on it
    doc["movements"][1]["observation_points"] = {"o1": [0.001, -0.002], "o2": [0.0, 0.0]}
    doc["movements"][2]["observation_points"] = {"o1": [0.3, 0.498], "o2": [0.8, 0.8]}
    assert trust_reasons(doc) == [
        "the map collapsed: L3, L4 where the robot stood (a degenerate fit)"
    ]


def test_each_sign_of_a_wrong_map_is_a_reason() -> None:
    misfit = "skipped: resection does not fit the map (robust residual 7.0 deg > 2 eps)"
    diverged = "skipped: the map diverged with it (x) and re-initialization ... did not fit"
    # one movement that does not fit is tolerated, two are not
    assert trust_reasons(_doc(["ok"] * 8 + [misfit, "ok"])) == []
    assert trust_reasons(_doc(["ok"] * 8 + [misfit, diverged])) == [
        "the bearings of movement(s) 8, 9 do not fit the map"
    ]
    # 4 of 10 movements used
    assert trust_reasons(_doc(["ok"] * 4 + ["skipped: waiting"] * 6)) == [
        "only 4 of 10 movements are in the map"
    ]
    assoc = {
        "named": {"blue": ["blue#2", "blue#4", "blue#7"]},
        "catalog_count": {"blue": 8},
        "movements_with_unresolved": [],
        "final_map": {
            "blue": {"detections": 80, "named": 75, "in line": 0, "warning": "5 of 80 ..."},
            "red": {"detections": 3, "named": 3, "in line": 0},
        },
        "doubtful": {"blue#4": "seen in 2 of 9 keyframes where predicted"},
        "unconfirmed": {"blue#7": "seen 2 times since named", "blue#2": "seen once"},
    }
    doc = _doc(["ok"] * 10, assoc)
    assert trust_reasons(doc) == [
        "detections of blue that no name explains",
        "doubtful name(s) blue#4",
        "unconfirmed name(s) blue#2, blue#7",
    ]
    entry = trust_entry(doc)
    assert entry["trustworthy"] is False and len(entry["reasons"]) == 3
    doc["trust"] = entry
    line = result_line(doc)
    assert line.endswith(
        "; the map is NOT trustworthy: detections of blue that no name explains; "
        "doubtful name(s) blue#4; unconfirmed name(s) blue#2, blue#7"
    )
