"""Benchmark: the joint estimator's incremental update per movement (not in the default run).

10 movements of simulated bearings; for each movement, the time of ``JointSlam.process_movement``
split into the paper filter it runs as initializer and the joint map's own update (placement,
factors, iSAM2, outlier check, marginals). Yardstick, alternated in the same run: the paper
filter alone (``BearingSlam.process_movement`` on the same bearings). Goals (issue "Every bearing
counts"): the joint update at most 5 ms per movement with 4 landmarks and 50 ms with 30.
Run with ``python -m pytest tests/bench/test_bench_joint.py -s``.
"""

from __future__ import annotations

import math
import statistics
import time

import numpy as np
import pytest
from bench_runs import scattered_run

from pipeline.joint.estimator import JointSlam
from pipeline.slam import BearingSlam, MovementObservation, MovementResult
from pipeline.synthetic import PAPER_REFERENCE, SimulatedRun, simulate_bearings

EPS = math.radians(3.0)
ROUNDS = 5


def _run(n_landmarks: int, seed: int) -> SimulatedRun:
    if n_landmarks == 4:
        return simulate_bearings(10, np.random.default_rng(seed), eps_rad=EPS)
    return scattered_run(10, n_landmarks, np.random.default_rng(seed), EPS, 0.12)


def _timed_paper(slam: BearingSlam, spent: list[float]) -> None:
    inner = slam.process_movement

    def timed(obs: MovementObservation) -> MovementResult:
        tick = time.perf_counter()
        out = inner(obs)
        spent.append(time.perf_counter() - tick)
        return out

    slam.process_movement = timed  # type: ignore[method-assign]


@pytest.mark.parametrize(("n_landmarks", "goal_ms"), [(4, 5.0), (30, 50.0)])
def test_incremental_update_per_movement(n_landmarks: int, goal_ms: float) -> None:
    joint_ms: list[float] = []
    paper_ms: list[float] = []
    yard_ms: list[float] = []
    for r in range(ROUNDS):
        run = _run(n_landmarks, r)
        names = list(run.landmarks_world)
        slam = JointSlam(names, PAPER_REFERENCE, vision_error_rad=EPS, rng=np.random.default_rng(r))
        spent: list[float] = []
        _timed_paper(slam.paper, spent)
        yard = BearingSlam(
            names, PAPER_REFERENCE, vision_error_rad=EPS, rng=np.random.default_rng(r)
        )
        for obs in run.observations:  # alternated: joint, then the yardstick, per movement
            tick = time.perf_counter()
            slam.process_movement(obs)
            total = time.perf_counter() - tick
            joint_ms.append(1e3 * (total - spent[-1]))
            paper_ms.append(1e3 * spent[-1])
            tick = time.perf_counter()
            yard.process_movement(obs)
            yard_ms.append(1e3 * (time.perf_counter() - tick))
        assert len(slam.estimates) >= n_landmarks - 2 - 1
    med = statistics.median(joint_ms)
    print(
        f"\n{n_landmarks} landmarks: joint update median {med:.1f} ms (p90 "
        f"{np.percentile(joint_ms, 90):.1f}; goal <= {goal_ms:g}), initializer (paper filter) "
        f"{statistics.median(paper_ms):.1f} ms, yardstick paper filter alone "
        f"{statistics.median(yard_ms):.1f} ms, ratio joint/yardstick "
        f"{med / statistics.median(yard_ms):.2f}"
    )
