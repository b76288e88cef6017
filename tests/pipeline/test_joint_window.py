"""Old keyframes folded into a linear prior (pipeline/joint/window.py): the prior's information
against a Schur complement computed by hand, a bearing map solved with its old keyframes
marginalized against the same map solved whole; the joint estimator with a window against the
same estimator keeping every movement, both against the truth."""

from __future__ import annotations

import math
from dataclasses import replace

import gtsam
import numpy as np
import pytest

from data_schemas.errors import EstimationError
from data_schemas.paper_arena import PAPER_REFERENCE
from pipeline.frame_change import to_fl
from pipeline.joint import graph as g
from pipeline.joint.estimator import JointSlam
from pipeline.joint.state import FrozenBearings
from pipeline.joint.window import DEFAULT_WINDOW, MIN_WINDOW, marginalize
from pipeline.synthetic import SimulatedRun, scatter_landmarks, simulate_bearings


def _information(
    factor: gtsam.NonlinearFactor, values: gtsam.Values, keys: list[int]
) -> np.ndarray:
    """The information matrix of ``factor`` linearized at ``values``, in the order of ``keys``."""
    hessian = gtsam.HessianFactor(factor.linearize(values))
    dims = [2] * len(keys)
    out = np.zeros((sum(dims), sum(dims)))
    info = hessian.information()
    order = list(hessian.keys())
    offsets = np.cumsum([0, *dims])
    for i, ki in enumerate(keys):
        for j, kj in enumerate(keys):
            a, b = order.index(ki), order.index(kj)
            out[offsets[i] : offsets[i + 1], offsets[j] : offsets[j + 1]] = info[
                2 * a : 2 * a + 2, 2 * b : 2 * b + 2
            ]
    return out


def _no_covariance(keys: list[int]) -> np.ndarray:
    raise AssertionError("not asked for")


def test_marginal_prior_is_the_schur_complement_of_a_linear_chain() -> None:
    # points a - b - c on a line of relative measurements; a has a prior; b is marginalized
    a, b, c = (int(gtsam.symbol("p", i)) for i in range(3))
    s_prior, s_ab, s_bc, s_ac = 0.5, 0.2, 0.3, 0.7
    iso = gtsam.noiseModel.Isotropic.Sigma
    factors = [
        gtsam.PriorFactorPoint2(a, np.zeros(2), iso(2, s_prior)),
        gtsam.BetweenFactorPoint2(a, b, np.array([1.0, 0.0]), iso(2, s_ab)),
        gtsam.BetweenFactorPoint2(b, c, np.array([1.0, 0.0]), iso(2, s_bc)),
        gtsam.BetweenFactorPoint2(a, c, np.array([2.0, 0.0]), iso(2, s_ac)),
    ]
    values = gtsam.Values()
    for k, x in ((a, 0.1), (b, 1.2), (c, 1.9)):
        values.insert(k, np.array([x, -0.1]))
    done = marginalize(factors, values, [b], lambda keys: np.eye(2 * len(keys)))
    prior = done.prior
    assert prior is not None
    assert sorted(prior.keys()) == sorted([a, c])
    # by hand, per axis (the axes are independent and alike): information of (a, b, c)
    w_p, w_ab, w_bc, w_ac = (1 / s**2 for s in (s_prior, s_ab, s_bc, s_ac))
    lam = np.array(
        [
            [w_p + w_ab + w_ac, -w_ab, -w_ac],
            [-w_ab, w_ab + w_bc, -w_bc],
            [-w_ac, -w_bc, w_bc + w_ac],
        ]
    )
    keep = [0, 2]
    schur = lam[np.ix_(keep, keep)] - np.outer(lam[keep, 1], lam[1, keep]) / lam[1, 1]
    expected = np.kron(schur, np.eye(2))
    got = _information(prior, values, [a, c])
    np.testing.assert_allclose(got, expected, rtol=1e-9)
    # b's covariance: its conditional given a and c plus theirs (identity here) carried over
    gain = np.array([w_ab, w_bc]) / lam[1, 1]
    np.testing.assert_allclose(
        done.covariances[b], (1 / lam[1, 1] + gain @ gain) * np.eye(2), rtol=1e-9
    )


def _bearing_map(
    loop: bool = False,
) -> tuple[list[gtsam.NonlinearFactor], gtsam.Values, list[int], list[int]]:
    """Six keyframes along a line seeing four landmarks (exact bearings, a gauge on two
    landmarks, odometry between consecutive keyframes and with ``loop`` between the first and
    the third too); the keyframe and landmark keys."""
    rng = np.random.default_rng(4)
    lm = np.array([[0.0, 0.0], [1.0, 0.0], [0.3, 0.8], [0.9, 0.7]])
    poses = [gtsam.Pose2(-0.5 + 0.35 * i, -0.6 + 0.05 * i, 0.1 * i) for i in range(6)]
    lkeys = [g.landmark_key(j) for j in range(len(lm))]
    pkeys = [g.pose_key(i, 0) for i in range(len(poses))]
    noise = gtsam.noiseModel.Isotropic.Sigma(1, math.radians(0.5))
    odo = gtsam.noiseModel.Diagonal.Sigmas(np.array([0.05, 0.05, 0.02]))
    factors: list[gtsam.NonlinearFactor] = list(g.gauge_factors(lkeys[0], lkeys[1]))
    for pk, pose in zip(pkeys, poses, strict=True):
        for lk, p in zip(lkeys, lm, strict=True):
            factors.append(g.bearing_factor(pk, lk, float(pose.bearing(p).theta()), noise))
    for i, j in [(i, i + 1) for i in range(len(poses) - 1)] + ([(0, 2)] if loop else []):
        factors.append(
            gtsam.BetweenFactorPose2(pkeys[i], pkeys[j], poses[i].between(poses[j]), odo)
        )
    values = gtsam.Values()
    for lk, p in zip(lkeys, lm, strict=True):
        values.insert(lk, p + rng.normal(0.0, 0.05, 2))
    for pk, pose in zip(pkeys, poses, strict=True):
        values.insert(pk, pose.compose(gtsam.Pose2(*rng.normal(0.0, 0.03, 3))))
    return factors, values, pkeys, lkeys


def _solve(factors: list[gtsam.NonlinearFactor], values: gtsam.Values) -> gtsam.Values:
    graph = gtsam.NonlinearFactorGraph()
    for f in factors:
        graph.add(f)
    return g.solve_batch(graph, values)


@pytest.mark.parametrize("loop", [False, True])
def test_a_map_with_old_keyframes_marginalized_keeps_the_optimum_and_covariance(loop: bool) -> None:
    factors, values, pkeys, lkeys = _bearing_map(loop)
    whole = _solve(factors, values)
    old = pkeys[:3]
    touching = [f for f in factors if set(f.keys()) & set(old)]
    rest = [f for f in factors if not set(f.keys()) & set(old)]
    graph_whole = gtsam.NonlinearFactorGraph()
    for f in factors:
        graph_whole.add(f)
    m_whole = gtsam.Marginals(graph_whole, whole)

    def joint(keys: list[int]) -> np.ndarray:
        return np.asarray(m_whole.jointMarginalCovariance(keys).fullMatrix())

    done = marginalize(touching, whole, old, joint)
    prior = done.prior
    assert prior is not None
    # each old keyframe keeps the covariance it has in the whole map
    assert sorted(done.covariances) == sorted(old)
    for k in old:
        np.testing.assert_allclose(done.covariances[k], m_whole.marginalCovariance(k), rtol=1e-6)
    assert set(prior.keys()) == {*lkeys, pkeys[3]}  # the landmarks and the first keyframe kept
    kept = whole.extract([*lkeys, *pkeys[3:]])
    # moved away from the optimum, the reduced map comes back to it
    start = gtsam.Values(kept)
    for lk in lkeys[2:]:
        start.update(lk, kept.atPoint2(lk) + np.array([0.03, -0.02]))
    reduced = _solve([*rest, prior], start)
    for lk in lkeys:
        np.testing.assert_allclose(reduced.atPoint2(lk), whole.atPoint2(lk), atol=1e-6)
    # and has the whole map's marginal covariance of each landmark
    graph_reduced = gtsam.NonlinearFactorGraph()
    for f in [*rest, prior]:
        graph_reduced.add(f)
    m_reduced = gtsam.Marginals(graph_reduced, kept)
    for lk in lkeys[2:]:
        np.testing.assert_allclose(
            m_reduced.marginalCovariance(lk), m_whole.marginalCovariance(lk), rtol=1e-6
        )


def test_no_prior_when_nothing_remains() -> None:
    k = g.pose_key(0, 0)
    prior = gtsam.PriorFactorPose2(k, gtsam.Pose2(), gtsam.noiseModel.Isotropic.Sigma(3, 1.0))
    values = gtsam.Values()
    values.insert(k, gtsam.Pose2())
    done = marginalize([prior], values, [k], _no_covariance)
    assert done.prior is None
    np.testing.assert_allclose(done.covariances[k], np.eye(3), rtol=1e-9)


def test_frozen_bearings_add_and_drop_a_landmark() -> None:
    fb = FrozenBearings.empty().plus(
        np.array([2, 3, 2]), np.array([0.1, -0.2, 0.3]), np.array([False, True, False])
    )
    fb = fb.plus(np.array([3]), np.array([0.4]), np.array([False]))
    assert len(fb) == 4
    less = fb.without(2)
    assert less.landmark.tolist() == [3, 3]
    assert less.residual_rad.tolist() == [-0.2, 0.4]
    assert less.rejected.tolist() == [True, False]


# ---------------------------------------------------------------- the joint estimator's window
EPS = math.radians(3.0)


def _long_run(n: int, seed: int, **arena: object) -> SimulatedRun:
    """``n`` movements with driven distances (2% noise), as ``process`` gives them."""
    rng = np.random.default_rng(seed)
    run = simulate_bearings(n, rng, eps_rad=EPS, **arena)  # type: ignore[arg-type]
    lengths = np.hypot(*(run.o2_world - run.o1_world).T)
    obs = [
        replace(o, distance_m=float(d * (1.0 + rng.normal(0.0, 0.02))))
        for o, d in zip(run.observations, lengths, strict=True)
    ]
    return replace(run, observations=obs)


def _mapped(run: SimulatedRun, seed: int, window: int | None, **kw: object) -> JointSlam:
    slam = JointSlam(
        list(run.landmarks_world),
        PAPER_REFERENCE,
        vision_error_rad=EPS,
        rng=np.random.default_rng(seed),
        distance_prior_rel=0.05,
        window=window,
        **kw,  # type: ignore[arg-type]
    )
    for obs in run.observations:
        slam.process_movement(obs)
    return slam


def _landmark_error(slam: JointSlam, run: SimulatedRun) -> float:
    truth = run.truth_fl()
    return float(np.mean([np.hypot(*(e.mean_fl - truth[n])) for n, e in slam.estimates.items()]))


def _keyframe_errors(slam: JointSlam, run: SimulatedRun, movements: range) -> np.ndarray:
    """Distances (FL) of the O1 keyframes of ``movements`` from where the robot was."""
    l1, l2 = run.landmarks_world["L1"], run.landmarks_world["L2"]
    poses = slam.keyframe_poses()
    return np.array(
        [np.hypot(*(poses[k, 0].origin_fl - to_fl(run.o1_world[k], l1, l2))) for k in movements]
    )


@pytest.mark.slow
def test_a_windowed_map_stays_bounded_and_as_accurate_as_the_whole_one() -> None:
    run = _long_run(120, 3)
    windowed, whole = (
        _mapped(run, 3, window=50, n_r=30, n_l=100),
        _mapped(run, 3, window=None, n_r=30, n_l=100),
    )
    # the oldest 50 movements left the graph once the map held 100; the rest are in it
    assert sorted(windowed._state.frozen) == list(range(50))
    assert sorted(windowed._state.placed) == list(range(50, 120))
    assert not windowed._map.isam.valueExists(g.pose_key(49, 1))
    assert windowed._map.isam.valueExists(g.pose_key(50, 0))
    # every movement is still reported, frozen ones where they were when they left
    assert windowed.used_movements == whole.used_movements == list(range(120))
    poses, whole_poses = windowed.keyframe_poses(), whole.keyframe_poses()
    assert sorted(poses) == sorted(whole_poses)
    trajectory = windowed.movement_poses()
    assert list(trajectory) == list(range(120))
    for k in range(50):
        np.testing.assert_array_equal(trajectory[k].o1_fl, poses[k, 0].origin_fl)
        assert trajectory[k].heading_rad == poses[k, 0].heading_rad
    # as accurate as the whole map, landmarks and old keyframes, against the truth
    assert _landmark_error(windowed, run) <= 1.2 * _landmark_error(whole, run) + 1e-3
    old = range(50)
    assert (
        np.median(_keyframe_errors(windowed, run, old))
        <= 1.2 * np.median(_keyframe_errors(whole, run, old)) + 1e-3
    )
    # an old keyframe's covariance is the whole map's when it left: never below the final one
    # (the map only learnt since), and not far above it
    ratios = [np.trace(poses[k].cov) / np.trace(whole_poses[k].cov) for k in poses if k[0] < 50]
    assert min(ratios) >= 0.95 and max(ratios) <= 2.0


def test_forgetting_a_landmark_takes_it_out_of_the_prior_and_history_skips_frozen_movements() -> (
    None
):
    run = _long_run(110, 5)
    slam = _mapped(run, 5, window=50, n_r=30, n_l=100)
    # the oldest 50 movements left the graph once the map held 100
    assert sorted(slam._state.frozen) == list(range(50))
    assert sorted(slam._state.placed) == list(range(50, 110))
    assert not slam._map.isam.valueExists(g.pose_key(49, 1))
    assert slam.used_movements == list(range(110))
    assert slam._state.prior is not None
    key = g.landmark_key(slam._lm_index["L3"])
    assert key in list(slam._state.prior.keys())
    slam.forget("L3")
    assert "L3" not in slam.estimates
    assert slam._state.prior is not None and key not in list(slam._state.prior.keys())
    assert not (slam._state.frozen_bearings.landmark == slam._lm_index["L3"]).any()
    truth = run.truth_fl()
    assert np.hypot(*(slam.estimates["L4"].mean_fl - truth["L4"])) < 0.05
    # its history comes back for the movements in the graph only
    first_live = min(slam._state.placed)
    slam.add_history("L3", [(0, 0, 0.3), (first_live, 1, 0.2)])
    assert [b.movement for b in slam._state.pending["L3"]] == [first_live]
    assert all(b.landmark != "L3" for b in slam._state.frozen[0].movement.bearings)


def test_window_shorter_than_the_careful_start_is_refused() -> None:
    run = _long_run(2, 1)
    with pytest.raises(EstimationError, match="window"):
        _mapped(run, 1, window=MIN_WINDOW - 1)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_a_long_windowed_map_of_16_landmarks_is_as_accurate_as_the_whole_one(seed: int) -> None:
    rng = np.random.default_rng(seed)
    ref = {"L1": (1.2, 1.7), "L2": (1.8, 1.7)}
    pts = scatter_landmarks(rng, ref, 16, (0.05, 0.05), (2.95, 1.95), 0.12)
    run = _long_run(
        400, seed, sigma_frac=1 / 3, landmarks_world=pts, arena_m=(3.0, 2.0), move_m=(0.3, 0.6)
    )
    small = {"n_r": 30, "n_l": 100}  # the initializer only seeds
    windowed = _mapped(run, seed, window=DEFAULT_WINDOW, **small)
    whole = _mapped(run, seed, window=None, **small)
    assert len(windowed._state.frozen) >= 250
    assert _landmark_error(windowed, run) <= 1.2 * _landmark_error(whole, run) + 1e-3
    old = range(200)
    assert (
        np.median(_keyframe_errors(windowed, run, old))
        <= 1.2 * np.median(_keyframe_errors(whole, run, old)) + 1e-3
    )
