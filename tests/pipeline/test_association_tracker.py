"""Association over synthetic runs (fixed seeds): identical landmarks named correctly, none
invented, the catalog count respected, hidden landmarks reported as not visible."""

from __future__ import annotations

import importlib
import math

import pytest
from alike_synthetic import run_synthetic

from pipeline.association import lifecycle

# the package exports the function under the module's name
assign_module = importlib.import_module("pipeline.association.assign")

SEEDS = (3, 4, 5)


@pytest.fixture(scope="module")
def runs() -> list:  # type: ignore[type-arg]
    return [run_synthetic(8, seed) for seed in SEEDS]


@pytest.mark.slow  # three 20-movement runs, about 2 s
def test_named_detections_are_correct_and_nothing_is_invented(runs: list) -> None:  # type: ignore[type-arg]
    for run in runs:
        assert len(run.estimates_fl) <= 8
        matched = run.matched()
        assert len(set(matched.values())) == len(matched)  # one name per true landmark
        assert max(run.errors_m().values()) <= 0.10  # every name stands on a real landmark
        assert len(run.given) >= 80  # association is at work (names come after 4 lines of sight)
    # right among the named bearings, pooled: a run has about 140, so one wrong bearing moves
    # its share by 0.7 points (seed 5: 139 of 142; the 20 seeds below are held to 99 %)
    right = sum(run.correct_share() * len(run.given) for run in runs)
    assert right >= 0.98 * sum(len(run.given) for run in runs)


@pytest.mark.slow  # twenty 20-movement runs, about 8 s
def test_detections_given_a_name_are_given_the_right_one_and_only_one() -> None:
    # pooled over 20 seeds (about 3,000 bearings)
    runs = [run_synthetic(8, seed) for seed in range(1, 21)]
    given = [g for run in runs for g in run.given]
    right = sum(run.correct_share() * len(run.given) for run in runs)
    assert len(given) >= 2500 and right >= 0.99 * len(given)
    # a detection goes to one name only: at its keyframe, or with a name it helped find (the
    # search once gave a second name to detections a confirmed hypothesis had been named from:
    # 9 such in 6 of these runs)
    for run in runs:
        keys = [
            (a.index, end, b)
            for a in run.results
            for end, bearings in enumerate((a.bearings_o1_rad, a.bearings_o2_rad))
            for name, b in bearings.items()
            if "#" in name
        ]
        keys += [
            (m, end, b) for a in run.results for rays in a.history.values() for m, end, b in rays
        ]
        assert len(keys) == len(set(keys))


@pytest.mark.slow  # three 20-movement runs, about 2 s
def test_most_landmarks_are_named_within_twenty_movements(runs: list) -> None:  # type: ignore[type-arg]
    assert sum(len(r.estimates_fl) for r in runs) >= 0.85 * 8 * len(runs)


def test_no_more_names_than_the_catalog_has() -> None:
    run = run_synthetic(8, 5, capacity=3)
    assert sorted(run.associator.named["blue"]) == ["blue#1", "blue#2", "blue#3"]
    beyond = [r for r in run.results if "blue beyond catalog" in r.unresolved]
    assert (
        beyond
        and "the catalog has 3 of blue, all named; not mapped"
        in (beyond[0].unresolved["blue beyond catalog"])
    )


def test_a_hidden_landmark_is_not_visible_not_misassociated() -> None:
    # B7 (named at movement 3 with seed 4) hidden (behind another landmark, say) from movement
    # 8 on: it is predicted but not detected, and its name is given to no other blob. (Not
    # every landmark of this run fares so: hidden from movement 8, B1, B3, B4 or B5 lets its
    # name take the blob of a landmark not named yet that lines up with its prediction;
    # docs/RESULTS.md.)
    def hide(move: int, end: int, name: str) -> bool:
        return name == "B7" and move >= 8

    run = run_synthetic(8, 4, hide=hide)
    b7 = next(n for n, t in run.matched().items() if t == "B7")
    late = [r for r in run.results if r.index >= 8]
    hidden = [r for r in late if f"{b7}@O1" in r.not_visible or f"{b7}@O2" in r.not_visible]
    assert len(hidden) >= len(late) // 2
    assert "not detected (hidden or out of range)" in next(iter(hidden[0].not_visible.values()))
    assert not any(name == b7 for m, _, name, _ in run.given if m >= 8)
    assert run.correct_share() >= 0.98


@pytest.mark.slow  # eight 20-movement runs, about 4 s
def test_a_post_hidden_behind_a_nearer_one_is_reported_hidden_and_its_blob_named(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # posts of 1 cm (as in the simulator): one hides another when their extents overlap, and
    # the blob is the front one's. With both named, the one clearly nearer takes the blob and
    # the other is "hidden behind" it; each such report is true.
    seeds = (2, 4, 7, 8)
    runs = [run_synthetic(8, seed, post_radius_m=0.01) for seed in seeds]
    hidden = [
        (run, r.index, key, why.rpartition("hidden behind ")[2])
        for run in runs
        for r in run.results
        for key, why in r.not_visible.items()
        if "hidden behind" in why
    ]
    assert len(hidden) >= 15
    for run, index, key, front in hidden:
        name, _, where = key.partition("@")
        end = 0 if where == "O1" else 1
        assert run.matched()[name] in run.occluded_at[index, end]
        # the blob went to the landmark in front, and it is that landmark's
        assert (index, end, front, run.matched()[front]) in run.given
    assert all(run.correct_share() >= 0.98 for run in runs)
    monkeypatch.setattr(assign_module, "NEAR_RATIO", 0.0)  # no landmark is ever clearly nearer
    without = [run_synthetic(8, seed, post_radius_m=0.01) for seed in seeds]
    # without the rule those blobs go to no one (measured: 15 more named with it; 31 before
    # names the search found could be doubtful, which keeps them out of the rule)
    assert sum(len(r.given) for r in runs) > sum(len(r.given) for r in without)


@pytest.mark.parametrize("hidden", ["B1", "B4"])
def test_a_hidden_landmark_whose_name_catches_other_blobs_is_reported_doubtful(
    hidden: str,
) -> None:
    # hidden from movement 8 on, B1 and B4 of seed 4 let their names take blobs of landmarks
    # not named yet that line up with their predictions (not fixed; docs/RESULTS.md): the
    # name is then seen at too few of its predictions and ends doubtful, so the wrong bearings
    # are not a silent error
    def hide(move: int, end: int, name: str) -> bool:
        return name == hidden and move >= 8

    run = run_synthetic(8, 4, hide=hide)
    name = next(n for n, t in run.matched().items() if t == hidden)
    caught = [m for m, _, n, true in run.given if m >= 8 and n == name and true != hidden]
    assert len(caught) >= 5  # else the run no longer shows the catch
    assert name in run.results[-1].doubtful


def test_a_movement_with_three_reference_bearings_is_chained_and_associated() -> None:
    # L2 hidden at O2 in every third movement from movement 6 on: three bearings of distinct
    # landmarks are too few for a resection, but such a movement starts where the last one
    # ended (the robot turns in place), so the bearings at each end fix its heading and length
    # and association goes on in it
    def hide(move: int, end: int, name: str) -> bool:
        return name == "L2" and end == 1 and move >= 6 and move % 3 == 0

    run = run_synthetic(8, 4, hide=hide)
    hidden = [r.index for r in run.results if r.index >= 6 and r.index % 3 == 0]
    assert not any("too few bearings" in why for r in run.results for why in r.unresolved.values())
    named = {m for m, *_ in run.given}
    assert set(hidden) <= named  # blobs named in every such movement
    assert run.correct_share() >= 0.98


@pytest.mark.parametrize("seed", SEEDS)
def test_landmarks_the_hypotheses_never_name_are_found_from_their_unnamed_detections(
    seed: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    # no hypothesis can be confirmed: every name comes from the search over the unnamed
    # detections of the last movements; the catalog has one name more than the arena has
    # landmarks, so a name on the crossing of rays of several landmarks would show. One does
    # in seed 4 (blue#8, 45 cm off, named with movement 13 along 4 lines of sight; every
    # landmark is seen at every keyframe here, so the point's class is always in its gate
    # before its naming): it is seen at none of its 12 predictions since, and reported doubtful
    monkeypatch.setattr(lifecycle, "CONFIRM_POSITIONS", 99)
    run = run_synthetic(8, seed, capacity=9)
    matched = run.matched()
    assert len(set(matched.values())) == len(matched) >= 7
    assert max(run.errors_m().values()) <= 0.03
    assert set(run.estimates_fl) - set(matched) <= set(run.results[-1].doubtful)  # reported
    assert run.correct_share() >= 0.98


def test_without_the_search_such_landmarks_stay_unnamed(monkeypatch: pytest.MonkeyPatch) -> None:
    # the same run with the search off names nothing: the test above tests the search
    monkeypatch.setattr(lifecycle, "CONFIRM_POSITIONS", 99)
    monkeypatch.setattr(lifecycle, "DISCOVER_KEYFRAMES", 10**6)
    run = run_synthetic(8, SEEDS[0], capacity=9)
    assert not run.estimates_fl
    assert any("blue unexplained" in r.unresolved for r in run.results)


@pytest.mark.slow  # six 30-movement runs, about 3 s
def test_a_narrow_camera_view_is_not_counted_as_misses() -> None:
    # blue landmarks seen only within +-45 deg of the heading: told the view, the associator
    # reports those predicted outside it as outside the field of view (not missed), so their
    # hypotheses and names survive; not told, every one out of view is a miss, and no
    # hypothesis lives long enough to be named
    view = (-math.radians(45.0), math.radians(45.0))
    told = [run_synthetic(8, seed, moves=30, view_rad=view) for seed in SEEDS]
    blind = [run_synthetic(8, seed, moves=30, view_rad=view, tell_view=False) for seed in SEEDS]
    assert all(
        any(
            "outside the camera's field of view" in v
            for r in run.results
            for v in r.not_visible.values()
        )
        for run in told
    )
    assert not any(
        "field of view" in v for run in blind for r in run.results for v in r.not_visible.values()
    )
    named_told = sum(len(run.estimates_fl) for run in told)
    named_blind = sum(len(run.estimates_fl) for run in blind)
    assert named_told >= 6 and named_told > named_blind
