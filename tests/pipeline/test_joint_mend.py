"""A joint map stuck away from its optimum: the evidence that says so (robustness.stuck,
unit_misfit, record_error) on hand-built states (the mend of a whole run:
tests/replay/test_joint_mend_run.py)."""

from __future__ import annotations

import math

import gtsam
import numpy as np

from pipeline.joint import graph as g
from pipeline.joint import robustness
from pipeline.joint.mapgraph import MapGraph
from pipeline.joint.state import JointSettings, MapState, Movement

EPS = math.radians(3.0)
NAMES = ("L1", "L2", "L3")


def _settings(distance_prior_rel: float | None = None) -> JointSettings:
    return JointSettings(
        landmarks=NAMES,
        reference=("L1", "L2"),
        eps_rad=EPS,
        sigma0_rad=EPS / 2.0,
        robust=True,
        turn_prior_sigma_rad=None,
        distance_prior_rel=distance_prior_rel,
        divergence_rms_rad=EPS,
    )


def _reference_rows(n: int, n_rejected: int, name: str = "L2") -> tuple[MapState, MapGraph]:
    """A map whose table holds ``n`` bearings of ``name`` (one per keyframe), the first
    ``n_rejected`` of them rejected."""
    settings = _settings()
    state = MapState.empty(settings)
    graph = MapGraph(settings)
    rows = [g.Bearing(i // 2, i % 2, name, 0.1 * i) for i in range(n)]
    graph.table.add(rows, settings.index, set(rows[:n_rejected]))
    return state, graph


def test_a_reference_landmark_mostly_rejected_makes_the_map_stuck() -> None:
    state, graph = _reference_rows(6, 4)
    assert robustness.stuck(state, graph) == "4 of 6 bearings of the reference landmark L2 rejected"
    state, graph = _reference_rows(7, 4, name="L1")
    assert robustness.stuck(state, graph).startswith("4 of 7 bearings of the reference landmark L1")


def test_half_rejected_too_few_bearings_or_another_landmark_is_not_stuck() -> None:
    assert robustness.stuck(*_reference_rows(6, 3)) == ""  # half is not most
    assert robustness.stuck(*_reference_rows(5, 5)) == ""  # too few to tell
    assert robustness.stuck(*_reference_rows(8, 8, name="L3")) == ""  # not the frame's


def _lengths_map(
    lengths_fl: list[float], distances_m: list[float | None], fl_per_m: float
) -> tuple[MapState, MapGraph]:
    """Movements along x of the given lengths (FL) with the given driven distances, and the
    map's scale at ``fl_per_m``; the distance prior's std 0.05."""
    settings = _settings(distance_prior_rel=0.05)
    state = MapState.empty(settings)
    graph = MapGraph(settings)
    values = gtsam.Values()
    for k, (length, d) in enumerate(zip(lengths_fl, distances_m, strict=True)):
        state.placed[k] = Movement(k, None, [], d)
        values.insert(g.pose_key(k, 0), gtsam.Pose2(0.0, float(k), 0.0))
        values.insert(g.pose_key(k, 1), gtsam.Pose2(length, float(k), 0.0))
    values.insert(g.SCALE_KEY, np.array([math.log(fl_per_m)]))
    graph.values = values
    return state, graph


def test_lengths_that_disagree_with_the_driven_distances_make_the_map_stuck() -> None:
    # 2 FL per metre: lengths 1 FL are 0.5 m; driven 0.5, 0.6 and 0.35 m:
    # |log(1 / (2 * d))| = 0, log 1.2 = 0.182, |log 0.7| = 0.357 -> median 0.182 > 3 * 0.05
    state, graph = _lengths_map([1.0, 1.0, 1.0], [0.5, 0.6, 0.35], 2.0)
    assert math.isclose(robustness.unit_misfit(state, graph), math.log(1.2), rel_tol=1e-9)
    assert "disagree with the driven distances by 0.18" in robustness.stuck(state, graph)
    # 0.5, 0.55 and 0.45 m: median |log| = |log 1.1| = 0.095 < 0.15
    state, graph = _lengths_map([1.0, 1.0, 1.0], [0.5, 0.55, 0.45], 2.0)
    assert math.isclose(robustness.unit_misfit(state, graph), math.log(1.1), rel_tol=1e-9)
    assert robustness.stuck(state, graph) == ""


def test_two_distances_or_no_scale_say_nothing_about_the_unit() -> None:
    state, graph = _lengths_map([1.0, 1.0, 1.0], [0.5, None, 0.1], 2.0)
    assert robustness.unit_misfit(state, graph) == 0.0
    state, graph = _lengths_map([1.0, 1.0, 1.0], [0.5, 0.6, 0.35], 2.0)
    values = gtsam.Values(graph.values)
    values.erase(g.SCALE_KEY)
    graph.values = values
    assert robustness.unit_misfit(state, graph) == 0.0


def test_the_record_error_counts_a_rejected_bearing_through_the_huber_loss() -> None:
    """One keyframe pair, L3 at (0.5, 1) seen from O1 = (0, 0) heading 0 with a bearing 0.2 rad
    off its direction: Huber loss at k = 1.345 std of a whitened error of 0.2 / sigma."""
    settings = _settings()
    state = MapState.empty(settings)
    graph = MapGraph(settings)
    true_rad = math.atan2(1.0, 0.5)
    b = g.Bearing(0, 0, "L3", true_rad + 0.2)
    state.placed[0] = Movement(0, None, [b])
    state.in_graph.add("L3")
    state.rejected.add(b)
    graph.retable(state)
    values = gtsam.Values()
    values.insert(g.pose_key(0, 0), gtsam.Pose2(0.0, 0.0, 0.0))
    values.insert(g.pose_key(0, 1), gtsam.Pose2(1.0, 0.0, 0.0))
    for name, xy in (("L1", (0.0, 0.0)), ("L2", (1.0, 0.0)), ("L3", (0.5, 1.0))):
        values.insert(settings.key(name), np.array(xy))
    graph.values = values
    e = 0.2 / state.sigma_model_rad
    k = 1.345
    huber = k * abs(e) - 0.5 * k * k  # beyond k: the linear part
    assert math.isclose(robustness.record_error(state, graph), huber, rel_tol=1e-6)
    assert state.rejected == {b}  # the map's state is left as it was


def _landmark_near_a_keyframe(l3_fl: tuple[float, float]) -> tuple[MapState, MapGraph]:
    """One movement from (0, 0) to (1, 0.5), L1 and L2 at (0, 2) and (1, 2) (values only, no
    gauge), and L3 at ``l3_fl`` (FL)."""
    settings = _settings()
    state = MapState.empty(settings)
    graph = MapGraph(settings)
    state.placed[0] = Movement(0, None, [])
    state.in_graph.add("L3")
    values = gtsam.Values()
    values.insert(g.pose_key(0, 0), gtsam.Pose2(0.0, 0.0, 0.0))
    values.insert(g.pose_key(0, 1), gtsam.Pose2(1.0, 0.5, 0.0))
    for name, xy in (("L1", (0.0, 2.0)), ("L2", (1.0, 2.0)), ("L3", l3_fl)):
        values.insert(settings.key(name), np.array(xy))
    graph.values = values
    return state, graph


def test_a_landmark_where_the_robot_stood_means_the_map_collapsed() -> None:
    # distances by hand: from (1.003, 0.5) to the keyframe at (1, 0.5) 0.003 < 0.005 FL;
    # from (1.004, 0.504) 0.0057; from (0.5, 0.25) 0.56 to either end
    assert robustness.collapsed(*_landmark_near_a_keyframe((1.003, 0.5)))
    assert not robustness.collapsed(*_landmark_near_a_keyframe((1.004, 0.504)))
    assert not robustness.collapsed(*_landmark_near_a_keyframe((0.5, 0.25)))
