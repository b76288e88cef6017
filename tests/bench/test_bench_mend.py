"""Benchmark: what the check for a stuck map costs the joint estimator per movement (not in the
default run).

After every movement (up to 50 movements) the estimator asks ``pipeline.joint.robustness.stuck``
whether the map is stuck away from its optimum (docs/method.md, step 6). Simulated bearings
(``pipeline.synthetic``, 12 landmarks in 3 x 2 m, 40 movements, driven distances with 2% noise,
the distance prior ``process`` uses); none of these maps is stuck, so the check is all the
difference. Each run is processed with the check and with it off (``stuck`` replaced by one that
finds nothing), the two alternated run by run; CPU time (``time.process_time``) of the whole
run's ``process_movement``. Yardstick: the run without the check. Goal: the ratio of the sums
over a round's runs at most 1.03, median over rounds.
Run with ``python -m pytest tests/bench/test_bench_mend.py -s -n 0``.
"""

from __future__ import annotations

import math
import statistics
import time

import numpy as np
import pytest
from bench_runs import scattered_run, with_distances

from pipeline.joint import robustness
from pipeline.joint.estimator import JointSlam
from pipeline.synthetic import SimulatedRun

EPS = math.radians(3.0)
ROUNDS = 3
RUNS = 6
MOVEMENTS = 40


def _run(seed: int) -> SimulatedRun:
    rng = np.random.default_rng(seed)
    return with_distances(scattered_run(MOVEMENTS, 12, rng, EPS, 0.15), rng)


def _cpu_s(run: SimulatedRun, seed: int) -> tuple[float, int]:
    """CPU seconds of the run's movements, and how many times the map was mended."""
    slam = JointSlam(
        list(run.landmarks_world),
        ("L1", "L2"),
        vision_error_rad=EPS,
        rng=np.random.default_rng(seed),
        distance_prior_rel=0.05,
    )
    tick = time.process_time()
    for obs in run.observations:
        slam.process_movement(obs)
    return time.process_time() - tick, len(slam.mends)


def test_the_stuck_map_check_costs_little_per_movement(monkeypatch: pytest.MonkeyPatch) -> None:
    check = robustness.stuck
    runs = [_run(seed) for seed in range(RUNS)]
    ratios = []
    for r in range(ROUNDS):
        spent = {True: 0.0, False: 0.0}
        for i, run in enumerate(runs):
            for on in (True, False) if (i + r) % 2 else (False, True):
                monkeypatch.setattr(robustness, "stuck", check if on else lambda *a: "")
                cpu, mends = _cpu_s(run, i)
                assert mends == 0  # an ordinary map: the check is all the difference
                spent[on] += cpu
        ratios.append(spent[True] / spent[False])
        print(f"round {r}: with the check {spent[True]:.2f} s, without {spent[False]:.2f} s")
    ratio = statistics.median(ratios)
    print(f"CPU with / without the check, median over {ROUNDS} rounds: {ratio:.3f}")
    assert ratio <= 1.03
