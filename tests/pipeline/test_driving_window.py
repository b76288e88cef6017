"""The driving map's window: old keyframes marginalized out of iSAM2, against a batch solve of
the whole graph (GTSAM's Levenberg-Marquardt and Marginals) and against keeping every keyframe."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
from driving_runs import run_drive

from data_schemas.errors import EstimationError
from pipeline.driving.estimator import DrivingOptions, DrivingSlam
from pipeline.driving.evaluate import similarity_fit
from pipeline.driving.factors import fixed_sensor_bearing_factor, keyframe_key
from pipeline.driving.simulate import arenas
from pipeline.joint.graph import landmark_key


def _drive(arena: str, seed: int, duration_s: float, options: DrivingOptions) -> DrivingSlam:
    return run_drive(arena, seed, duration_s, options)[2]


def test_fixed_sensor_bearing_matches_gtsam_bearing_factor() -> None:
    noise = gtsam.noiseModel.Isotropic.Sigma(1, 0.01)
    sensor = np.array([1.0, -2.0, 2.5])
    values = gtsam.Values()
    values.insert(keyframe_key(0), gtsam.Pose2(*sensor))
    values.insert(landmark_key(0), np.array([-3.0, 1.5]))  # behind-left: near the +-pi seam
    for bearing in (0.3, -2.9, 3.1):
        ours = fixed_sensor_bearing_factor(landmark_key(0), sensor, bearing, noise)
        ref = gtsam.BearingFactor2D(keyframe_key(0), landmark_key(0), gtsam.Rot2(bearing), noise)
        assert ours.error(values) == pytest.approx(ref.error(values), rel=1e-9, abs=1e-12)
        a, rhs_a = ours.linearize(values).jacobian()
        b, rhs_b = ref.linearize(values).jacobian()
        # gtsam's columns: the pose's 3, then the point's 2; ours: the point's 2
        assert a == pytest.approx(b[:, 3:5], rel=1e-9, abs=1e-12)
        assert rhs_a == pytest.approx(rhs_b, rel=1e-9, abs=1e-12)


def test_window_keeps_the_newest_keyframes_and_freezes_the_others() -> None:
    opts = DrivingOptions(window_keyframes=10, window_stride=5, settle_keyframes=0)
    slam = _drive("square", 3, 60.0, opts)
    n = slam.n_keyframes
    assert n > 30
    live = n - len(slam.frozen)
    assert 10 <= live < 15 + 1  # the window, up to its stride (and the last keyframe)
    est = slam.isam.calculateEstimate()
    assert not est.exists(keyframe_key(len(slam.frozen) - 1))
    assert est.exists(keyframe_key(len(slam.frozen)))
    traj = slam.trajectory_m()
    assert traj.shape == (n, 3)
    assert traj[: len(slam.frozen)] == pytest.approx(np.array(slam.frozen))


def test_young_landmarks_hold_their_keyframes_up_to_twice_the_window() -> None:
    # settling: keyframes seeing a landmark that entered lately stay, iSAM2 grows up to
    # 2 * window + stride keyframes; without it the window and its stride
    frozen = {}
    for settle in (0, 10**6):
        opts = DrivingOptions(window_keyframes=10, window_stride=5, settle_keyframes=settle)
        slam = _drive("square", 3, 60.0, opts)
        live = slam.n_keyframes - len(slam.frozen)
        assert 10 <= live <= (15 if settle == 0 else 25) + 1
        frozen[settle] = len(slam.frozen)
    assert 0 < frozen[10**6] < frozen[0]


def test_windowed_map_is_the_whole_graphs_optimum() -> None:
    # oracle: Levenberg-Marquardt over every factor of the drive (slam.graph: the old keyframes
    # and their bearings included), from the windowed estimate; its Marginals give the map's
    # own uncertainty. The window's linearization of old factors must move the landmarks by a
    # small part of that uncertainty (keeping every keyframe: under 0.02 sigma here).
    slam = _drive("square", 3, 120.0, DrivingOptions(window_keyframes=50, window_stride=25))
    assert len(slam.frozen) >= 25
    values = gtsam.Values()
    for k, pose in enumerate(slam.trajectory_m()):
        values.insert(keyframe_key(k), gtsam.Pose2(*pose))
    mapped = slam.landmarks_m()
    for name, p in mapped.items():
        values.insert(landmark_key(slam.index[name]), p)
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-12)
    params.setAbsoluteErrorTol(1e-14)
    params.setMaxIterations(100)
    best = gtsam.LevenbergMarquardtOptimizer(slam.graph, values, params).optimize()
    marginals = gtsam.Marginals(slam.graph, best)
    assert len(mapped) == 8
    for name, p in mapped.items():
        key = landmark_key(slam.index[name])
        cov = marginals.marginalCovariance(key)
        d = p - best.atPoint2(key)
        assert float(d @ np.linalg.solve(cov, d)) < 0.1**2, name  # within 0.1 sigma


def test_window_none_keeps_every_keyframe() -> None:
    slam = _drive("square", 3, 40.0, DrivingOptions(window_keyframes=None))
    assert slam.frozen == []
    assert slam.isam.calculateEstimate().exists(keyframe_key(0))


def test_window_under_one_keyframe_is_refused() -> None:
    with pytest.raises(EstimationError, match="at least 1"):
        DrivingSlam(
            ["A", "B"],
            ("A", "B"),
            vision_error_rad=0.02,
            rng=np.random.default_rng(0),
            options=DrivingOptions(window_keyframes=0),
        )


# (arena, seed): a room, a corridor with landmarks entering late, far landmarks
LONG = [("square", 21), ("square", 22), ("long", 21), ("long", 22), ("far", 21), ("far", 22)]


@pytest.mark.slow
@pytest.mark.parametrize(("arena", "seed"), LONG)
def test_window_maps_as_well_as_every_keyframe(arena: str, seed: int) -> None:
    a = arenas()[arena]
    errs = []
    for window in (50, None):
        slam = _drive(arena, seed, 300.0, DrivingOptions(window_keyframes=window, window_stride=25))
        pts = slam.landmarks_m()
        names = sorted(pts)
        truth = np.array([a.landmarks_world[n] for n in names])
        _, err = similarity_fit(np.array([pts[n] for n in names]), truth)
        errs.append((len(names), float(err.mean())))
    (n_w, e_w), (n_all, e_all) = errs
    assert n_w == n_all
    assert e_w <= 1.1 * e_all, (e_w, e_all)
