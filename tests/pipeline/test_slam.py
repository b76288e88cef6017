"""The public estimator on simulated bearings of the paper's arena (no images)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from pipeline import BearingSlam, MovementObservation, batch_least_squares
from pipeline.synthetic import PAPER_REFERENCE, simulate_bearings

EPS = math.radians(3.0)
NAMES = ["L1", "L2", "L3", "L4"]
SEEDS = range(1000, 1040)
N_MOVES = 10


def _only(
    obs: list[MovementObservation], keep: set[str], used: set[int]
) -> list[MovementObservation]:
    return [
        MovementObservation(
            o.index,
            {k: v for k, v in o.bearings_o1_rad.items() if k in keep},
            {k: v for k, v in o.bearings_o2_rad.items() if k in keep},
        )
        for o in obs
        if o.index in used
    ]


@dataclass
class Trials:
    err_by_move: np.ndarray  # (seeds, moves, 2) error of L3, L4 after each movement (nan: none)
    err_final: np.ndarray  # (seeds, 2)
    err_ls: np.ndarray  # (seeds, 2): LS on the same bearings the filter used, per landmark
    covered: np.ndarray  # (seeds, 2)


@pytest.fixture(scope="module")
def trials() -> Trials:
    by_move, final, ls, cov = [], [], [], []
    for seed in SEEDS:
        rng = np.random.default_rng(seed)
        run = simulate_bearings(N_MOVES, rng, eps_rad=EPS)
        truth = run.truth_fl()
        slam = BearingSlam(NAMES, PAPER_REFERENCE, vision_error_rad=EPS, rng=rng)
        rows = []
        for obs in run.observations:
            est = slam.process_movement(obs).estimates
            rows.append(
                [
                    np.linalg.norm(est[n].mean_fl - truth[n]) if n in est else np.nan
                    for n in ("L3", "L4")
                ]
            )
        by_move.append(rows)
        est = slam.estimates
        final.append([np.linalg.norm(est[n].mean_fl - truth[n]) for n in ("L3", "L4")])
        cov.append([est[n].contains(truth[n], 0.8) for n in ("L3", "L4")])
        used = set(slam.used_movements)
        row = []
        for n in ("L3", "L4"):
            sol = batch_least_squares(
                _only(run.observations, {"L1", "L2", n}, used), NAMES, PAPER_REFERENCE
            )
            row.append(np.linalg.norm(sol[n] - truth[n]))
        ls.append(row)
    return Trials(np.array(by_move), np.array(final), np.array(ls), np.array(cov))


def test_error_falls_with_movements(trials: Trials) -> None:
    e = np.nanmean(trials.err_by_move, axis=(0, 2))
    assert e[9] < e[2] < e[0]
    assert e[9] < 0.5 * e[0]


@pytest.mark.xfail(
    strict=True,
    reason="measured: the paper's per-landmark product fusion is 1.26x (seeds 1000-1039) to 1.46x "
    "(seeds 0-79) the LS error on the same bearings; see docs/method.md",
)
def test_particle_error_is_close_to_batch_least_squares(trials: Trials) -> None:
    ratio = trials.err_final.mean() / trials.err_ls.mean()
    assert ratio < 1.25, f"particle / LS error = {ratio:.3f}"


@pytest.mark.xfail(
    strict=True,
    reason="measured: the 80% ellipse covers the truth in 64-71% of trials (overconfident); "
    "see docs/method.md",
)
def test_credible_region_is_calibrated(trials: Trials) -> None:
    rate = trials.covered.mean()
    assert 0.70 <= rate <= 0.90, f"80% region covers the truth in {rate:.2%} of trials"


def test_skipped_movement_leaves_state_unchanged() -> None:
    rng = np.random.default_rng(0)
    run = simulate_bearings(3, rng, eps_rad=EPS)
    slam = BearingSlam(NAMES, PAPER_REFERENCE, vision_error_rad=EPS, rng=rng)
    ok = [r for r in map(slam.process_movement, run.observations) if r.status == "ok"]
    assert ok
    before = {k: v.copy() for k, v in slam.belief_fl.items()}
    used = list(slam.used_movements)
    o = next(o for o in run.observations if o.index == ok[0].index)
    missing = MovementObservation(
        o.index, {k: v for k, v in o.bearings_o1_rad.items() if k != "L2"}, o.bearings_o2_rad
    )
    res = slam.process_movement(missing)
    assert res.status.startswith("skipped: reference landmark 'L2'")
    assert res.skipped_landmarks["L2"] == "not seen at O1"
    assert slam.used_movements == used
    for k, v in slam.belief_fl.items():
        np.testing.assert_array_equal(v, before[k])


def test_result_shapes() -> None:
    rng = np.random.default_rng(1)
    run = simulate_bearings(2, rng, eps_rad=EPS)
    slam = BearingSlam(NAMES, PAPER_REFERENCE, vision_error_rad=EPS, rng=rng, frame_change="exact")
    for obs in run.observations:
        res = slam.process_movement(obs)
        if res.status == "ok":
            break
    assert res.status == "ok"
    assert {"L1", "L2"} <= set(res.particles_fr)
    assert all(v.shape == (50, 2) for v in res.particles_fr.values())
    assert all(v.shape == (300, 2) for v in res.particles_fl.values())
    assert res.o1_fl.shape == (2500, 2) and res.o2_fl.shape == (2500, 2)
    assert set(res.estimates) <= {"L3", "L4"}
    assert len(slam.trajectory_fl) == 1
    for c1, c2 in res.cones_fr.values():
        assert np.all(np.isfinite(c1)) and np.all(np.isfinite(c2))
