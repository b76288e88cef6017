"""Association on the real simulator: 8 identical landmarks and a distinct reference pair,
both camera models, one fixed seed each (a run where every landmark gets named); the goals of
issue 11 checked on it. Over 10 seeds per camera the goals are not all met (a run may leave a
landmark unnamed after 20 movements, or name one off its landmark): ``test_association_over_seeds``
and ``tests/bench/test_bench_association.py``, figures in docs/RESULTS.md.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from alike_scenarios import alike_arena, alike_scenario
from alike_scoring import Score, score_log
from click.testing import CliRunner
from test_rerun import _read

from data_schemas.codec import validate
from pipeline.association.final import MISSING_UNEXPLAINED
from replay.cli import cli
from replay.experiments.run import simulate
from tests.mcap_reader import LogReader


def _simulated(camera: str, seed: int, folder: Path) -> tuple[Path, Score]:
    """Simulate the 8-landmark layout of ``seed`` with ``camera`` into ``folder``; score it."""
    log = folder / f"{camera}_{seed}.mcap"
    simulate(alike_scenario(8, camera, layout_seed=seed), log, seed=seed)
    return log, score_log(log)


def _arena_scored(
    n: int, size_m: tuple[float, float], seed: int, folder: Path, camera: str = "omni"
) -> Score:
    """Simulate ``n`` identical landmarks in an arena of ``size_m`` drawn from ``seed`` (seen
    by ``camera``) into ``folder``; score it."""
    log = folder / "run.mcap"
    simulate(alike_arena(n, camera, size_m, seed=seed), log, seed=seed)
    return score_log(log)


def _off_names(camera: str, seed: int, folder: Path) -> tuple[Path, Score, set[str]]:
    """A simulated run whose layout fools the confirmation: its names more than 10 cm off in
    the last movement's map (before anything is retracted once the log is processed)."""
    log, s = _simulated(camera, seed, folder)
    off = {n for n, e in s.errors_last_m.items() if e > 0.10}
    assert off  # the layout still fools the confirmation: else the test tests nothing
    return log, s, off


def _doubtful_last(s: Score) -> dict[str, str]:
    """The names doubtful after the last movement (name -> why)."""
    last = s.summary["movements"][-1].get("ambiguous_landmarks", {})
    return {k.removesuffix(" doubtful"): w for k, w in last.items() if k.endswith(" doubtful")}


def _retracted_at_end(s: Score) -> dict[str, str]:
    """Names retracted once the log was processed (name -> why)."""
    return dict(s.summary["association"]["final_map"]["blue"].get("retracted", {}))


def _processed(log: Path, folder: Path) -> tuple[str, dict[str, Any]]:
    """``bslam process LOG --out``: its output, and the derived log's association message
    (checked against its schema)."""
    out = folder / "derived.mcap"
    result = CliRunner().invoke(cli, ["process", str(log), "--out", str(out)])
    assert result.exit_code == 0, result.output
    with LogReader(out) as reader:
        msg: dict[str, Any] = next(m.decode() for m in reader.messages(["/pipeline/association"]))
    validate("bslam.Association", msg)
    return result.output, msg


def _replayed(log: Path, folder: Path) -> tuple[list[str], dict[str, list[dict[str, Any]]]]:
    """``bslam replay`` of ``log`` read back with Rerun's reader: the map's last labels, and
    the rows per entity."""
    rrd = folder / "run.rrd"
    result = CliRunner().invoke(cli, ["replay", str(log), "--save", str(rrd)])
    assert result.exit_code == 0, result.output
    rows = _read(rrd)
    last = [r["Points2D:labels"] for r in rows["/map/estimates"] if r.get("Points2D:labels")][-1]
    return list(last), rows


@pytest.fixture(
    scope="module",
    # the omni run takes about 5 s: CI runs it with -m slow
    params=[("unwrapped", 2), pytest.param(("omni", 2), marks=pytest.mark.slow)],
    ids=lambda p: p[0],
)
def scored(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Score:
    camera, seed = request.param
    return _simulated(camera, seed, tmp_path_factory.mktemp(f"alike_{camera}"))[1]


def test_detections_are_associated_correctly(scored: Score) -> None:
    # issue 11's goal: >= 98 % of detections associated correctly; a detection is either named
    # correctly, or left unnamed and reported (never forced): at most 2 % named wrongly
    assert scored.wrong_share <= 0.02
    # not correct by naming nothing: most detections get their name, at their keyframe or with
    # the name they led to (``named_from``). One run's share moves with the order in which
    # its landmarks are named (this one, unwrapped: 91, 92 and 85 % over the last three
    # versions), so the share is checked pooled over ten runs per camera
    # (test_association_over_seeds); here, at least three in four
    assert scored.n_correct >= 0.75 * scored.n_detections
    # among the named ones alone the share is lower (docs/RESULTS.md): a blob of a landmark
    # not yet named that lines up with a named one is taken for it
    assert scored.correct_share >= 0.9


def test_the_final_map_names_nearly_every_detection_and_names_it_right(scored: Score) -> None:
    # once the log is processed every keyframe detection is associated again with the final
    # map: all of them are there, more are named than movement by movement, and issue 11's
    # goal holds over all the detections (measured: 99.3 % unwrapped, 100 % omni; movement
    # by movement 91.7 and 90.9 %)
    assert scored.n_final_detections == scored.n_detections
    assert scored.n_final_named > scored.n_associated
    assert scored.n_final_correct >= 0.98 * scored.n_final_detections
    assert scored.n_final_correct >= 0.995 * scored.n_final_named
    # every name right and every landmark named: nothing left for a warning
    assert "warning" not in scored.summary["association"]["final_map"]["blue"]


def test_every_landmark_is_mapped_and_none_invented(scored: Score) -> None:
    assert scored.n_named == scored.n_true == 8
    # one-to-one and close: no name stands for a landmark that is not there
    assert len(set(scored.matched.values())) == 8
    assert max(scored.errors_m.values()) <= 0.10
    assert sum(scored.errors_m.values()) / 8 <= 0.03


def test_the_summary_names_and_reports(scored: Score) -> None:
    doc = scored.summary
    assert doc["association"]["named"] == {"blue": [f"blue#{k}" for k in range(1, 9)]}
    assert set(doc["landmarks"]) == {f"blue#{k}" for k in range(1, 9)}
    # before the first names every blob is unexplained: reported, not mapped
    first = doc["movements"][0]
    assert "explained by no named landmark" in first["ambiguous_landmarks"]["blue unexplained"]
    assert not first["landmarks"]
    # each name comes with the detections it was named from: four lines of sight at least,
    # from this movement and earlier ones, none given to a name at its own keyframe
    named = [m for m in doc["movements"] if m.get("named_landmarks")]
    assert sorted(n for m in named for n in m["named_landmarks"]) == sorted(doc["landmarks"])
    for m in named:
        assert set(m["named_from"]) == set(m["named_landmarks"])
        for rays in m["named_from"].values():
            assert len(rays) >= 4
            assert all(r["movement"] <= m["index"] and r["at"] in ("O1", "O2") for r in rays)
            for r in rays:
                then = doc["movements"][r["movement"]]["bearings_deg"]
                end = 0 if r["at"] == "O1" else 1
                assert all(pair[end] != r["bearing_deg"] for pair in then.values())


@pytest.mark.parametrize("camera", ["unwrapped", pytest.param("omni", marks=pytest.mark.slow)])
def test_movements_with_few_identified_bearings_are_placed_by_matching(
    camera: str, tmp_path: Path
) -> None:
    # seed 231: at movements 12-15 the robot sees at most one landmark of its own at a
    # keyframe; placed from the identified bearings alone, four movements were left out and
    # 79 % of the detections named right with the final map (omni). Matched against the map
    # from where movement 11 ended, every movement is placed.
    _, s = _simulated(camera, 231, tmp_path)
    assert [m["status"] for m in s.summary["movements"]] == ["ok"] * 20
    final = s.summary["association"]["final_map"]["blue"]
    assert final["not placed"] == 0
    assert "placed_by_matching" not in s.summary["association"]
    assert s.n_final_correct >= 0.98 * s.n_final_detections
    assert s.n_final_correct >= 0.995 * s.n_final_named


@pytest.mark.parametrize("camera", ["unwrapped", pytest.param("omni", marks=pytest.mark.slow)])
def test_movements_before_the_map_began_are_placed_for_the_final_association(
    camera: str, tmp_path: Path
) -> None:
    # seed 275: the reference pair is not seen from both keyframes of movements 0 and 1, so
    # the map starts at movement 2 and they stay out of it; once the log is processed they
    # are placed backwards from movement 2's start by matching their detections with the
    # final map, and their detections are associated (30 of them "not placed" before)
    log, s = _simulated(camera, 275, tmp_path)
    assert [m["status"] for m in s.summary["movements"][:2]] != ["ok", "ok"]
    assert s.summary["association"]["placed_by_matching"] == [0, 1]
    final = s.summary["association"]["final_map"]["blue"]
    assert final["not placed"] == 0
    assert s.n_final_correct >= 0.98 * s.n_final_detections
    assert s.n_final_correct >= 0.995 * s.n_final_named
    # the derived log says the same
    output, msg = _processed(log, tmp_path)
    assert "% with the final map, movement(s) 0, 1 placed by matching)" in output
    assert msg["placed_by_matching"] == [0, 1]


@pytest.mark.parametrize("camera", ["unwrapped", pytest.param("omni", marks=pytest.mark.slow)])
def test_a_landmark_never_named_during_the_run_is_named_at_the_end(
    camera: str, tmp_path: Path
) -> None:
    # seed 168: one landmark stands where, from most of the robot's keyframes, it lines up with
    # a named one a few degrees away; the run ends with 7 names. With the final map its
    # detections are told apart and left unexplained, their rays meet at it, and the free name
    # goes to it.
    log, s = _simulated(camera, 168, tmp_path)
    last = s.summary["movements"][-1]["landmarks"]
    assert sum(n.startswith("blue#") for n in last) == 7
    final = s.summary["association"]["final_map"]["blue"]
    (name,) = final["named_at_end"]
    assert name == "blue#8"
    assert "named once the log was processed" in final["named_at_end"][name]
    assert s.n_named == s.n_true == 8
    assert len(set(s.matched.values())) == 8
    assert max(s.errors_m.values()) <= 0.10
    assert sum(s.errors_m.values()) / 8 <= 0.03
    assert s.n_final_correct >= 0.98 * s.n_final_detections
    output, msg = _processed(log, tmp_path)
    assert "with the final map, blue#8 named where detections no name explained meet" in output
    assert [r["name"] for r in msg["named_at_end"]] == ["blue#8"]
    assert "blue#8" in {r["name"] for r in msg["landmarks"]}


@pytest.mark.slow
@pytest.mark.parametrize("camera", ["unwrapped", "omni"])
def test_association_over_seeds(camera: str, tmp_path: Path) -> None:
    # issue 11's goals for 8 identical landmarks beyond a distinct reference pair, on ten
    # layouts per camera: in every run all 8 named, each name on its own landmark (none twice,
    # none more than 10 cm off, mean <= 3 cm), and with the final map at least 98 % of the
    # ten runs' detections associated right. Measured: 99.45 % (unwrapped) and 99.48 % (omni),
    # none wrong (the rest contested or unexplained, and said so), every run at 97.3 % or more,
    # worst landmark 3.0 and 3.8 cm. Before the names under suspicion were given anew once the
    # log was processed (docs/RESULTS.md), omni seed 3 ended with two names 28 and 47 cm off.
    correct = final = detections = wrong = false_warnings = 0
    for seed in range(1, 11):
        _, s = _simulated(camera, seed, tmp_path)
        assert s.n_named == 8 and len(set(s.matched.values())) == 8, seed
        assert max(s.errors_m.values()) <= 0.10, (seed, s.errors_m)
        assert sum(s.errors_m.values()) / 8 <= 0.03, (seed, s.errors_m)
        assert s.n_final_correct >= 0.97 * s.n_final_detections, seed
        correct += s.n_correct
        final += s.n_final_correct
        wrong += s.n_final_named - s.n_final_correct
        detections += s.n_detections
        false_warnings += "warning" in s.summary["association"]["final_map"]["blue"]
    assert final >= 0.98 * detections, (final, detections)
    assert wrong <= 0.005 * detections, wrong  # what is not right is mostly said to be unsure
    # at their keyframes (or with the name they led to), before the final map: 88.2 / 86.4 %
    assert correct >= 0.85 * detections, (correct, detections)
    assert false_warnings <= 1  # every name right: a warning would be false (measured: none)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("camera", "seed", "edge"), [("unwrapped", 201, "B1"), ("omni", 396, "B3")]
)
def test_a_landmark_seen_from_a_narrow_fan_is_named_by_the_search(
    camera: str, seed: int, edge: str, tmp_path: Path
) -> None:
    # layouts with a landmark near the arena's edge that the robot sees only from a narrow fan
    # of directions (B1 of unwrapped 201: its lines of sight span about 22 degrees, 3 of them
    # distinct); no hypothesis gets the 4 lines of sight a name needs, so it stayed unnamed.
    # The search names it from 12 keyframes or more along 3 lines of sight when its class was
    # detected at 90 % of its predictions: all 8 named, on their landmarks, none doubtful.
    from pipeline.association.lifecycle import DISCOVER_FAN_KEYFRAMES

    _, s = _simulated(camera, seed, tmp_path)
    assert s.n_named == 8 and len(set(s.matched.values())) == 8
    assert max(s.errors_m.values()) <= 0.10, s.errors_m
    name = next(n for n, t in s.matched.items() if t == edge)
    assert s.errors_m[name] <= 0.03
    rays = [r for m in s.summary["movements"] for r in m.get("named_from", {}).get(name, ())]
    assert len(rays) >= DISCOVER_FAN_KEYFRAMES
    assert "doubtful" not in s.summary["association"]


@pytest.mark.slow
@pytest.mark.parametrize(("camera", "seed"), [("unwrapped", 185), ("omni", 187)])
def test_a_doubtful_name_is_retracted_for_a_landmark_the_full_catalog_kept_out(
    camera: str, seed: int, tmp_path: Path
) -> None:
    # layouts where a name given early is seen at few of its predictions (found on seeds
    # 161-420): blue#4 of unwrapped 185 (named with movement 4, seen at 3 of 14) and blue#6 of
    # omni 187 (movement 6, 3 of 12) become doubtful, and once every name is given and a real
    # landmark is confirmed, the most doubtful name goes to it: the final map has all 8 on
    # their landmarks
    _, s = _simulated(camera, seed, tmp_path)
    retracted = {
        k.removesuffix(" retracted"): why
        for m in s.summary["movements"]
        for k, why in m.get("ambiguous_landmarks", {}).items()
        if k.endswith(" retracted")
    }
    assert retracted  # else this layout tests nothing
    assert all("retracted: the name goes to a landmark of blue" in w for w in retracted.values())
    assert s.n_named == 8 and len(set(s.matched.values())) == 8
    assert max(s.errors_m.values()) <= 0.10, s.errors_m
    assert "doubtful" not in s.summary["association"]


@pytest.mark.slow
@pytest.mark.parametrize(("camera", "seed"), [("unwrapped", 213), ("omni", 213)])
def test_names_off_their_landmark_are_reported_doubtful(
    camera: str, seed: int, tmp_path: Path
) -> None:
    # a layout where a name given to rays of several landmarks stays (blue#5 of unwrapped 213
    # and blue#6 of omni 213, 31 cm off, each seen at 13 of 26 predictions):
    # seen too rarely where the map predicts it, it is reported as doubtful in the summary,
    # its result line and Rerun; the names on real landmarks are not, but for one the search
    # among unnamed detections found (blue#8, 1.5 cm off, whose blobs are as often another
    # landmark's: the search's doubt, see below)
    from replay.process import result_line

    log, s, off = _off_names(camera, seed, tmp_path)
    doubtful = _doubtful_last(s)
    assert off <= set(doubtful)
    assert all("keyframes where predicted since it was named" in doubtful[n] for n in off)
    assert all("found by the search" in doubtful[n] for n in set(doubtful) - off)
    # once the log is processed, the name off goes to the landmark it kept out: the final
    # map has every name on its landmark, and says so
    assert set(_retracted_at_end(s)) == off and max(s.errors_m.values()) <= 0.10
    final_doubtful = s.summary["association"]["doubtful"]
    assert set(final_doubtful) == set(doubtful) - off
    assert f"doubtful: {', '.join(sorted(final_doubtful))}" in result_line(s.result)
    assert f"with the final map, {', '.join(sorted(off))} given anew" in result_line(s.result)
    # and in Rerun: the final map labels the doubtful names, the log says why (read back
    # with Rerun's reader)
    last, rows = _replayed(log, tmp_path)
    labelled = {n.removesuffix(" (doubtful)") for n in last if n.endswith(" (doubtful)")}
    assert labelled == set(final_doubtful)
    texts = [t for r in rows["/log"] for t in r.get("TextLog:text") or ()]
    assert all(any(f"{n} doubtful: seen at" in t for t in texts) for n in off)
    assert all(any(t.startswith(f"with the final map, {n} seen at") for t in texts) for n in off)
    # and every name's first detections
    for m in s.summary["movements"]:
        for n, rays in m.get("named_from", {}).items():
            assert any(f"{m['index']}: {n} named from {len(rays)} detections" in t for t in texts)


@pytest.mark.slow
@pytest.mark.parametrize("camera", ["unwrapped", "omni"])
def test_names_the_search_found_off_their_landmark_are_reported_doubtful(
    camera: str, tmp_path: Path
) -> None:
    # layout 204: blue#2, found by the search among unnamed detections, stands 38 cm off any
    # landmark; it is seen at about half of its predictions, contested at about 40 %, and its
    # bearings do not scatter enough to tell. Its blobs are as often another landmark's: it is
    # reported doubtful with that reason, movement by movement and in Rerun's log. (blue#7,
    # found by the search late in the run, 12-17 cm off, is doubtful too; the names on real
    # landmarks are not.)
    from replay.process import result_line

    log, s, off = _off_names(camera, 204, tmp_path)
    doubtful = _doubtful_last(s)
    assert set(doubtful) == off and {"blue#2", "blue#7"} <= off
    assert "found by the search among unnamed detections" in doubtful["blue#2"]
    # once the log is processed, association and map made to agree, both are given anew where
    # their detections and the unexplained ones meet: every name within 10 cm of its landmark
    # (the truth measured directly), none left doubtful (with one pass of the final
    # association blue#7 stayed doubtful, 12-17 cm off)
    assert set(_retracted_at_end(s)) == {"blue#2", "blue#7"}
    assert max(s.errors_m.values()) <= 0.10, s.errors_m
    assert not s.summary["association"].get("doubtful")
    assert "doubtful:" not in result_line(s.result)
    last, rows = _replayed(log, tmp_path)
    assert not any(n.endswith(" (doubtful)") for n in last)
    texts = [t for r in rows["/log"] for t in r.get("TextLog:text") or ()]
    assert any("blue#2 doubtful: found by the search" in t for t in texts)


@pytest.mark.slow
@pytest.mark.parametrize("camera", ["unwrapped", "omni"])
def test_names_whose_bearings_scatter_are_reported_doubtful(camera: str, tmp_path: Path) -> None:
    # layout 338: a name (blue#4 unwrapped, blue#5 omni, 22-23 cm off) is seen at most of its
    # predictions, where landmarks line up with it in turn; its bearings in the map scatter
    # about it (11 such names in 440 runs of seeds 161-380 were reported by nothing else)
    from replay.process import result_line

    _, s, off = _off_names(camera, 338, tmp_path)
    doubtful = _doubtful_last(s)
    assert set(doubtful) == off
    assert all("bearings in the map scatter" in why for why in doubtful.values())
    # what became of them once the log was processed: retracted, or still doubtful
    final_doubtful = set(s.summary["association"].get("doubtful", {}))
    assert final_doubtful | set(_retracted_at_end(s)) == off
    if final_doubtful:
        assert f"doubtful: {', '.join(sorted(final_doubtful))}" in result_line(s.result)


@pytest.mark.slow
@pytest.mark.parametrize(("camera", "seed"), [("unwrapped", 33), ("omni", 33)])
def test_names_seen_too_few_times_to_tell_are_reported_unconfirmed(
    camera: str, seed: int, tmp_path: Path
) -> None:
    # layouts where the last landmark is named with movement 18 of 20: from its naming on, at
    # most 2 of its predictions come after it (4 confirm a name), so nothing can tell yet
    # whether it stands on a landmark. It ends unconfirmed in the summary, its result line and
    # Rerun, and is flagged from the movement that names it to the last; the names seen often
    # since end confirmed. (The wrong names this report is for, named too late for the doubt
    # rule to judge, were 2 of the 320 runs of seeds 1-160 before names often missed were made
    # doubtful, and none since, on seeds 1-320.)
    from replay.process import result_line

    log, s = _simulated(camera, seed, tmp_path)
    moves = s.summary["movements"]
    named_at = {n: m["index"] for m in reversed(moves) for n in m.get("named_landmarks", ())}
    late = {n for n, k in named_at.items() if k >= moves[-1]["index"] - 1}
    unconfirmed = s.summary["association"]["unconfirmed"]
    assert late and late <= set(unconfirmed) and "doubtful" not in s.summary["association"]
    assert len(unconfirmed) <= len(late) + 1 and s.n_named == 8
    assert all("keyframe(s) since it was named" in why for why in unconfirmed.values())
    assert f"unconfirmed: {', '.join(sorted(unconfirmed))}" in result_line(s.result)
    for name in late:
        flagged = [m["index"] for m in moves if name in m.get("unconfirmed_landmarks", {})]
        assert flagged[0] == named_at[name] and flagged[-1] == moves[-1]["index"]
    last, _ = _replayed(log, tmp_path)
    labelled = {n.removesuffix(" (unconfirmed)") for n in last if n.endswith(" (unconfirmed)")}
    assert labelled <= set(unconfirmed)  # a name not in the map yet has no label


@pytest.mark.slow
def test_a_name_off_its_landmark_is_retracted_once_the_log_is_processed(tmp_path: Path) -> None:
    # unwrapped seed 3 names all 8, blue#6 about 30 cm off, where rays of several landmarks
    # meet, and doubtful; the landmark it should be stays out of the map and its blobs are
    # left unexplained by the final map. Their rays meet at one point: once the log is
    # processed the doubtful name goes there, and the final map has all 8 on their landmarks
    log, s, off = _off_names("unwrapped", 3, tmp_path)
    assert off == {"blue#6"} and "blue#6" in _doubtful_last(s)
    assert set(_retracted_at_end(s)) == off
    assert s.n_named == 8 and max(s.errors_m.values()) <= 0.10
    assert "doubtful" not in s.summary["association"]
    output, msg = _processed(log, tmp_path)
    assert "with the final map, blue#6 given anew where" in output
    assert [r["name"] for r in msg["retracted"]] == ["blue#6"]
    final = {r["name"]: r["mean"] for r in msg["landmarks"]}
    assert final.keys() == s.summary["landmarks"].keys()
    assert final["blue#6"] == pytest.approx(s.summary["landmarks"]["blue#6"]["mean"], abs=1e-8)


@pytest.mark.slow
def test_two_names_between_two_landmarks_are_given_anew_once_the_log_is_processed(
    tmp_path: Path,
) -> None:
    # omni seed 3: B4 and B7 at the arena's left edge, 16 degrees apart from the path, seen
    # from its right only; the run names both from each other's rays (blue#6 and blue#8, 28
    # and 47 cm off, doubtful), the final map gives each some of both landmarks' detections
    # and leaves 19 unexplained, too few at any one point to name a landmark by themselves.
    # Their detections and the unexplained ones meet at two points: the names go there
    log, s, off = _off_names("omni", 3, tmp_path)
    assert off == {"blue#6", "blue#8"} and off <= set(_doubtful_last(s))
    retracted = _retracted_at_end(s)
    assert set(retracted) == off
    assert all("given anew once the log was processed" in why for why in retracted.values())
    assert s.n_named == 8 and len(set(s.matched.values())) == 8
    assert max(s.errors_m.values()) <= 0.03, s.errors_m
    assert s.n_final_correct == s.n_final_detections  # every detection right, none unexplained
    assert "warning" not in s.summary["association"]["final_map"]["blue"]
    output, msg = _processed(log, tmp_path)
    assert "with the final map, blue#6, blue#8 given anew where" in output
    assert sorted(r["name"] for r in msg["retracted"]) == ["blue#6", "blue#8"]


@pytest.mark.slow
def test_detections_a_name_off_its_landmark_leaves_behind_are_warned_about(
    tmp_path: Path,
) -> None:
    # unwrapped seed 499 (simulated after the rules were chosen) names all 8, blue#6 30 cm
    # off; no rule makes it doubtful, so nothing is retracted, but the final map leaves the
    # blobs of the landmark it kept out unexplained, and says where their rays meet
    log, s, off = _off_names("unwrapped", 499, tmp_path)
    final = s.summary["association"]["final_map"]["blue"]
    assert s.n_named == 8 and off == {"blue#6"} and "retracted" not in final
    assert final["unexplained"] >= MISSING_UNEXPLAINED
    assert "a landmark may be missing from the map" in final["warning"]
    assert "keyframes meet near" in final["warning"]
    output, msg = _processed(log, tmp_path)
    assert "with the final map, blue: detections no name explains" in output
    assert f"blue with the final map: {final['warning']}" in output  # a warning line
    assert msg["warnings"] == [{"class": "blue", "text": final["warning"]}]


@pytest.mark.slow  # two simulated 30-movement runs of 12 landmarks, 10-30 s each
@pytest.mark.parametrize("seed", [5, 6])
def test_a_map_broken_by_names_of_mixed_rays_is_mended_once_the_log_is_processed(
    seed: int, tmp_path: Path
) -> None:
    # 12 identical landmarks in 4 x 3 m, omni: names made during the run from rays of several
    # landmarks pulled the map; with one pass of the final association these runs ended with 9
    # and 7 names 11 cm to 2.4 m off and 61 % and 48 % of the detections right. Associating
    # with the final map and solving it again in turn puts every name within 10 cm of its
    # landmark (the truth measured directly) and names 9 in 10 detections right or more
    s = _arena_scored(12, (4.0, 3.0), seed, tmp_path)
    assert s.n_named == 12 and len(set(s.matched.values())) == 12
    assert max(s.errors_m.values()) <= 0.10, s.errors_m
    right, detections = s.n_final_correct, s.n_final_detections
    assert right >= 0.9 * detections, (right, detections)


@pytest.mark.slow  # one simulated 30-movement run of 12 landmarks, 5-10 s
def test_a_name_a_missing_landmark_lines_up_with_is_flagged(tmp_path: Path) -> None:
    # 12 identical landmarks in 4 x 3 m, omni, seed 21: B8 is never named, and the name on B1,
    # 37 cm from it, took some of its detections: it stands more than 10 cm off (the truth
    # measured directly) with a region of about 2.5 cm, which no other test flagged (main
    # before). From most keyframes the point where B8's unexplained detections meet lies in
    # that name's gate: it is weak, and says so
    s = _arena_scored(12, (4.0, 3.0), 21, tmp_path)
    blue = s.summary["association"]["final_map"]["blue"]
    assert "warning" in blue
    (pulled,) = [n for n, t in s.matched.items() if t == "B1"]
    assert s.errors_m[pulled] > 0.10, s.errors_m  # the scenario: else the test tests nothing
    assert blue["weak"][pulled].startswith("the landmark missing near"), blue["weak"]
    flagged = set(blue["weak"]) | set(s.summary["association"].get("doubtful", {}))
    assert {n for n, e in s.errors_m.items() if e > 0.10} <= flagged


@pytest.mark.slow  # one simulated 30-movement run of 12 landmarks, 5-10 s
def test_a_landmark_at_the_arena_edge_is_named_once_the_log_is_processed(tmp_path: Path) -> None:
    # 12 identical landmarks in 4 x 3 m, omni, seed 23: B11 stands 22 cm from the arena's edge
    # and the robot sees it only along 3 lines of sight; the search during the run, with its
    # 90 % test over the keyframes since the first ray, never got it past its naming, and the
    # final repair wanted 4 lines (main before: 10 of 12 named, 507 of 593 detections right).
    # Once the log is processed the fan's rays name it, and the one missing besides it too
    s = _arena_scored(12, (4.0, 3.0), 23, tmp_path)
    named_at_end = s.summary["association"]["final_map"]["blue"]["named_at_end"]
    fan = [n for n, why in named_at_end.items() if "along 3 lines of sight" in why]
    assert len(fan) == 1, named_at_end
    assert s.matched[fan[0]] == "B11", s.matched
    assert s.n_named == 12 and len(set(s.matched.values())) == 12
    assert max(s.errors_m.values()) <= 0.10, s.errors_m
    right, detections = s.n_final_correct, s.n_final_detections
    assert right >= 0.9 * detections, (right, detections)


@pytest.mark.slow  # one simulated 30-movement run of 16 landmarks, 10-20 s
def test_the_name_the_final_map_supports_least_goes_to_the_landmark_it_kept_out(
    tmp_path: Path,
) -> None:
    # 16 identical landmarks in 5 x 4 m, omni, seed 4: with every name given, the unexplained
    # detections meet at a landmark no name holds. A name in open space (given a detection at
    # a few % of its predictions with the final map) is not doubtful by its support during the
    # run, so a rule that retracts only doubtful names retracted a right one instead (main
    # before: blue#13, 3 cm off) and the ghost stayed 2.2 m off; 78 % of the detections right.
    # Retracting the name the final map supports least, when the point explains more
    # detections than it, puts that name on the landmark (the truth measured directly). (A
    # second name, 1.6 m off, then moves where the final map explains 25 more detections of
    # the class; it ends 86 cm off, flagged)
    s = _arena_scored(16, (5.0, 4.0), 4, tmp_path)
    retracted = _retracted_at_end(s)
    counted = {n: w for n, w in retracted.items() if "left unexplained meet (it was given" in w}
    assert len(counted) == 1, retracted
    ((name, why),) = counted.items()
    assert "the least of blue" in why
    assert name not in _doubtful_last(s)  # the old rule could not choose it
    assert s.errors_m[name] <= 0.10, s.errors_m
    right, detections = s.n_final_correct, s.n_final_detections
    assert right >= 0.85 * detections, (right, detections)


@pytest.mark.slow
def test_a_map_broken_during_the_run_is_built_again_from_the_first_movement(
    tmp_path: Path,
) -> None:
    # 16 identical landmarks in 5 x 4 m, omni, seed 6: names made of rays of several landmarks
    # entered the young map and misplaced its keyframes; the last movement's map holds a name
    # metres off, and the final rounds (which start from those keyframes) left one 4 m off and
    # 82 % of the detections right (main before). Built again from the first movement with the
    # final association's names, no mixed name enters early: every name the map holds is
    # within 20 cm of its landmark (the truth measured directly), at least 85 % right
    s = _arena_scored(16, (5.0, 4.0), 6, tmp_path)
    assert max(s.errors_last_m.values()) > 1.0, s.errors_last_m  # broken during the run
    assert max(s.errors_m.values()) <= 0.20, s.errors_m
    right, detections = s.n_final_correct, s.n_final_detections
    assert right >= 0.85 * detections, (right, detections)


@pytest.mark.slow  # one simulated 30-movement run of 12 landmarks, 5-10 s
def test_keyframes_their_own_landmarks_contradict_are_placed_again_for_the_final_association(
    tmp_path: Path,
) -> None:
    # 12 identical landmarks in 4 x 3 m, unwrapped, seed 5: the map holds movements 19-24
    # where their blue blobs fit other names (a keyframe turned by 99 degrees), and during the
    # run movements 21-25 see L2 8-23 degrees from where the map puts it. Associated from those
    # poses, 73 detections were named wrong, 77 % right (main before). A movement held where a
    # landmark of a class of its own is seen more than 2 eps off is placed again by matching
    # for the association, and the map is solved again from the poses matched: 9 in 10 right or
    # more (the truth measured directly), every landmark named within 10 cm. With the map left
    # where it held them (their detections only kept from the names' bearings), a name ended
    # 19 cm off
    s = _arena_scored(12, (4.0, 3.0), 5, tmp_path, camera="unwrapped")
    l2 = [m["residuals_deg"].get("L2") or [] for m in s.summary["movements"][21:26]]
    assert all(max(abs(r) for r in pair if r is not None) > 6.0 for pair in l2), l2  # the scenario
    assert s.n_named == 12 and len(set(s.matched.values())) == 12
    right, detections = s.n_final_correct, s.n_final_detections
    assert right >= 0.9 * detections, (right, detections)
    assert max(s.errors_m.values()) <= 0.10, s.errors_m


@pytest.mark.slow  # one simulated 30-movement run of 16 landmarks, 10-20 s
def test_a_name_moves_to_a_landmark_whose_blobs_a_named_neighbour_contests(
    tmp_path: Path,
) -> None:
    # 16 identical landmarks in 5 x 4 m, omni, seed 26: blue#3 stands where rays of several
    # landmarks meet, 2.1 m from the landmark the scoring pairs it with, given a detection at
    # 42 % of the keyframes where the map predicts it. The landmark it keeps out of the map
    # stands 31 cm from blue#12's and lies in its gate from 41 of 60 keyframes, so most of its
    # blobs are contested with or in line with blue#12's; only 24 are unexplained, fewer than
    # the 25 detections blue#3 had, and they do not meet with blue#3's own. Counting those 24
    # alone, the name stayed (main before: 800 of 871 right). With the name there, the final
    # map explains 36 more detections: it moves there, and every name ends within 10 cm of its
    # landmark (the truth measured directly)
    s = _arena_scored(16, (5.0, 4.0), 26, tmp_path)
    why = _retracted_at_end(s)["blue#3"]
    assert "left unexplained meet; with it there the final map explains" in why
    assert s.n_named == 16 and len(set(s.matched.values())) == 16
    assert max(s.errors_m.values()) <= 0.10, s.errors_m
    right, detections = s.n_final_correct, s.n_final_detections
    assert right >= 0.97 * detections, (right, detections)
