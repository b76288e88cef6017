"""The trust verdict of a summary (replay/trust.py) and the result line that says it."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from replay.process import result_line
from replay.sinks.summary import AssociationOutcome, FinalAssociation, RunSummary
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
    assert trust_entry(trust_reasons(doc)) == {"trustworthy": True}


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
    entry = trust_entry(trust_reasons(doc))
    assert entry == {"trustworthy": False, "reasons": trust_reasons(doc)}


def test_the_result_line_says_what_the_summary_holds() -> None:
    plain = RunSummary(
        movements=10, used=9, resected=2, reference=("L1", "L2"), landmarks=3, mean_error_m=0.0123
    )
    assert result_line(plain) == (
        "9/10 movements used (2 placed by resection), 3 landmarks mapped besides the reference "
        "pair L1, L2, mean error 1.2 cm"
    )
    alike = AssociationOutcome(
        names_given={"blue": 3},
        catalog_count={"blue": 8, "red": 2},
        detections=40,
        detections_named=30,
        movements_with_unresolved=(4, 6),
        doubtful=("blue#4",),
        unconfirmed=(),
        final=FinalAssociation(
            detections=80,
            explained=60,
            placed_by_matching=(0,),
            named_at_end=(),
            retracted=("blue#5",),
            missing=("blue",),
        ),
    )
    untrusted = replace(
        plain,
        resected=0,
        mean_error_m=None,
        bearing_noise_deg=0.456,
        association=alike,
        untrusted=("doubtful name(s) blue#4", "the map collapsed"),
    )
    assert result_line(untrusted) == (
        "9/10 movements used, 3 landmarks mapped besides the reference pair L1, L2, bearing "
        "noise 0.46 deg; alike landmarks named: blue 3/8, red 0/2, 75 % of 40 detections "
        "(75 % with the final map, movement(s) 0 placed by matching) (2 movement(s) with "
        "ambiguities); with the final map, blue#5 given anew where the detections no name "
        "explained point (under suspicion before); with the final map, blue: detections no "
        "name explains (a landmark may be missing); doubtful: blue#4 (seen too rarely where "
        "predicted, or bearings that scatter); the map is NOT trustworthy: doubtful name(s) "
        "blue#4; the map collapsed"
    )


def test_weak_and_loosely_placed_names_are_flagged_by_name() -> None:
    doc = _doc(["ok"] * 4)
    doc["map_unit_m"] = 0.5  # 1 FL = 50 cm
    # two names: each region at 99.5 %, sqrt(-2 ln 0.005) = 3.26 std; std 2 cm along the
    # widest axis (0.04 FL) reaches 6.5 cm; std 4 cm (0.08 FL) 13.0 cm, farther than 10 cm;
    # the unit's own landmark L3 is not named
    doc["landmarks"] = {
        "L3": {"mean": [0.5, 0.5], "cov": [[0.0064, 0.0], [0.0, 0.0064]]},
        "blue#2": {"mean": [0.2, 0.4], "cov": [[0.0016, 0.0], [0.0, 0.0001]]},
        "blue#10": {"mean": [0.9, 0.1], "cov": [[0.0001, 0.0], [0.0, 0.0064]]},
    }
    doc["association"] = {
        "named": {"blue": ["blue#2", "blue#3", "blue#10"]},
        "catalog_count": {"blue": 12},
        "movements_with_unresolved": [],
        "final_map": {
            "blue": {"detections": 80, "named": 70, "in line": 0, "weak": {"blue#3": "given"}}
        },
    }
    assert trust_reasons(doc) == [
        "weak name(s) blue#3 (with the final map, too few detections, detections that do not "
        "meet at one point, or a missing landmark in line with it)",
        "name(s) blue#10 placed only to within 10 cm or worse (their regions at 99 % for the "
        "run's names together)",
    ]
    summary = RunSummary(4, 4, 0, ("L1", "L2"), 3, untrusted=tuple(trust_reasons(doc)))
    assert "NOT trustworthy: weak name(s) blue#3" in result_line(summary)
    # without the map's unit, no distance can be judged
    del doc["map_unit_m"]
    assert trust_reasons(doc) == [
        "weak name(s) blue#3 (with the final map, too few detections, detections that do not "
        "meet at one point, or a missing landmark in line with it)"
    ]


def test_loosely_placed_is_judged_for_the_run_s_names_together() -> None:
    # std 3.2 cm along the widest axis (0.064 FL at 50 cm per FL): alone, the 99 % region
    # reaches sqrt(-2 ln 0.01) * 3.2 = 3.03 * 3.2 = 9.7 cm, within 10 cm; among 16 names each
    # region is at 1 - 0.01 / 16, sqrt(-2 ln(0.01 / 16)) = sqrt(14.76) = 3.84 std: 12.3 cm
    tight = {"mean": [0.3, 0.3], "cov": [[0.000001, 0.0], [0.0, 0.000001]]}  # std 0.05 cm
    doc = _doc(["ok"] * 4)
    doc["map_unit_m"] = 0.5
    doc["landmarks"] = {"blue#1": {"mean": [0.5, 0.5], "cov": [[0.004096, 0.0], [0.0, 0.0001]]}}
    assert trust_reasons(doc) == []
    doc["landmarks"] |= {f"blue#{k}": tight for k in range(2, 17)}
    assert trust_reasons(doc) == [
        "name(s) blue#1 placed only to within 10 cm or worse (their regions at 99 % for the "
        "run's names together)"
    ]


def _residual_doc(residuals: dict[str, list[list[float | None]]]) -> dict[str, Any]:
    """A map of 8 movements whose named landmarks have these residuals (deg) at O1, O2 of
    movement k, eps 3 deg (so the rejection bound is 6 deg)."""
    doc = _doc(["ok"] * 8)
    doc["method"] = {"vision_error_deg": 3.0}
    for k, m in enumerate(doc["movements"]):
        m["residuals_deg"] = {n: r[k] for n, r in residuals.items() if k < len(r)}
    return doc


def test_a_landmark_whose_bearings_mostly_miss_the_map_is_named() -> None:
    good = [[0.5, -0.4]] * 8
    # L4: 4 of its 8 bearings beyond 6 deg: half, not most (a landmark with wrong detections)
    half = [[7.0, 0.2], [-9.0, 0.1], [6.5, -0.3], [-6.1, 0.0]]
    assert trust_reasons(_residual_doc({"L1": good, "L3": good, "L4": half})) == []
    # L4: 6 of 9 beyond (a residual of exactly 6 deg is within the bound; None: not seen)
    most = [[7.0, 6.0], [-9.0, 0.1], [6.5, -12.0], [-6.1, 5.9], [None, 30.0]]
    assert trust_reasons(_residual_doc({"L1": good, "L4": most})) == [
        "landmark(s) L4 (6 of 9) whose bearings mostly lie more than 2 eps from the map (it "
        "stands elsewhere, or its detections are another's)"
    ]
    # all 4 of L5's bearings far, but too few to judge
    few = [[20.0, 20.0], [20.0, 20.0]]
    assert trust_reasons(_residual_doc({"L1": good, "L5": few})) == []


def test_a_reference_landmark_whose_bearings_miss_the_map_puts_the_frame_in_doubt() -> None:
    far = [[-15.5, 0.3], [-17.4, -8.9], [-11.9, -8.2], [-8.4, 1.0]]
    reasons = trust_reasons(_residual_doc({"L2": far, "L3": [[0.1, 0.2]] * 8}))
    assert reasons == [
        "6 of 8 bearings of the reference landmark L2 lie more than 2 eps from the map: the "
        "map's frame rests on it"
    ]
    # without the vision error bound nothing is judged
    doc = _residual_doc({"L2": far})
    del doc["method"]
    assert trust_reasons(doc) == []


def test_a_landmark_whose_bearings_scatter_is_named() -> None:
    # L3: |r| 0.7 and 1.2, robust scale 1.4826 x 0.95 = 1.41 deg; L4: half its bearings near
    # the map, half 3.7-4.6 deg off (all within 2 eps), robust scale 1.4826 x 3.75 = 5.56 deg
    l3 = [[0.7, -0.7], [1.2, -1.2]] * 4
    l4 = [[0.2, -0.3], [4.0, -4.5], [0.1, 3.8], [-4.2, 0.4], [4.4, -0.2], [-3.9, 4.1]]
    l4 += [[0.3, -4.6], [3.7, -0.1]]
    doc = _residual_doc({"L3": l3, "L4": l4})
    assert trust_reasons(doc) == []  # no noise estimate: nothing to compare with
    doc["bearing_noise_deg"] = 1.0
    assert trust_reasons(doc) == [
        "landmark(s) L4 (5.6x) whose bearings scatter about the map that many times as widely "
        "as the map's bearings do (its detections may be of several landmarks)"
    ]
    doc["bearing_noise_deg"] = 0.8  # L3: 1.41 / 0.8 = 1.76 > 1.7
    assert "L3 (1.8x), L4 (6.9x)" in trust_reasons(doc)[0]
    # too few bearings to judge (9), and a name of a shared class (association judges it)
    doc = _residual_doc({"L4": [*l4[:4], [0.2, None]], "red#1": l4})
    doc["bearing_noise_deg"] = 1.0
    assert trust_reasons(doc) == []


def test_a_landmark_whose_bearings_mostly_miss_is_not_named_twice() -> None:
    most = [[7.0, 6.5], [-9.0, 0.1], [6.5, -12.0], [-6.1, 8.9], [None, 30.0], [0.2, 0.1]]
    doc = _residual_doc({"L4": most})
    doc["bearing_noise_deg"] = 1.0
    assert trust_reasons(doc) == [
        "landmark(s) L4 (8 of 11) whose bearings mostly lie more than 2 eps from the map (it "
        "stands elsewhere, or its detections are another's)"
    ]
