"""Association of landmarks that look alike: cost per landmark per movement, and issue 11's
goals on the real simulator (not in the default run: ``pytest tests/bench``).

``test_association_scaling``: the joint estimator plus association over 20 synthetic movements
(no images) with 4, 8, 16 and 32 identical landmarks and a distinct reference pair, and the
time spent in association alone (``Associator.associate`` and ``hypothesize``); the
yardstick (the same run with every landmark of its own class, so no association) is measured
in the same run, alternated. ``test_association_goals``: 8 identical landmarks, 10 seeds per
camera model, scored like ``tests/replay/test_association_sim.py``; the figures are printed
and kept in ``extra_info`` (docs/RESULTS.md).
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pipeline.estimators import make_estimator
from pipeline.synthetic import simulate_bearings

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "replay"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "pipeline"))
from alike_scenarios import alike_scenario
from alike_scoring import score_log
from alike_synthetic import ARENA_M, EPS, layout, run_synthetic

MOVES = 20


def _yardstick(n: int, seed: int) -> float:
    """Seconds for the joint estimator alone over the same run, every landmark distinct."""
    rng = np.random.default_rng(seed)
    lms = layout(n, rng)
    sim = simulate_bearings(
        MOVES, rng, landmarks_world=lms, arena_m=ARENA_M, move_m=(0.2, 0.4), clearance_m=0.08
    )
    slam = make_estimator("joint", list(lms), ("L1", "L2"), vision_error_rad=EPS, rng=rng)
    tick = time.perf_counter()
    for obs in sim.observations:
        slam.process_movement(obs)
    return time.perf_counter() - tick


@pytest.mark.parametrize("n", [4, 8, 16, 32])
def test_association_scaling(benchmark: Any, n: int) -> None:
    with_assoc: list[float] = []
    assoc_only: list[float] = []
    without: list[float] = []

    def once() -> None:
        seed = len(with_assoc)
        run = run_synthetic(n, seed, moves=MOVES)
        with_assoc.append(run.seconds)
        assoc_only.append(run.association_seconds)
        without.append(_yardstick(n, seed))

    benchmark.pedantic(once, rounds=7, iterations=1)
    per = 1000.0 * float(np.median(with_assoc)) / MOVES / n
    own = 1000.0 * float(np.median(assoc_only)) / MOVES / n
    yard = 1000.0 * float(np.median(without)) / MOVES / n
    benchmark.extra_info["ms_per_landmark_per_movement"] = per
    benchmark.extra_info["association_ms_per_landmark_per_movement"] = own
    benchmark.extra_info["yardstick_ms_per_landmark_per_movement"] = yard
    print(
        f"\n{n} landmarks: {per:.2f} ms per landmark per movement (estimator + association), "
        f"association alone {own:.2f}; yardstick (joint estimator, landmarks distinct) {yard:.2f}"
    )


def test_association_goals(benchmark: Any, tmp_path: Path) -> None:
    rows = []

    def once() -> None:
        for camera in ("unwrapped", "omni"):
            for seed in range(1, 11):
                log = tmp_path / f"{camera}_{seed}.mcap"
                from replay.experiments.run import simulate

                simulate(alike_scenario(8, camera, layout_seed=seed), log, seed=seed)
                s = score_log(log)
                errs = list(s.errors_m.values())
                rows.append(
                    (
                        camera,
                        seed,
                        s.n_named,
                        len(set(s.matched.values())),
                        s.n_correct,
                        s.n_associated,
                        s.n_detections,
                        float(np.mean(errs)) if errs else math.nan,
                        max(errs, default=math.nan),
                    )
                )

    benchmark.pedantic(once, rounds=1, iterations=1)
    for r in rows:
        print(
            f"\n{r[0]:9s} seed {r[1]:2d}: named {r[2]}/8 (distinct truths {r[3]}), "
            f"correct {r[4]}/{r[5]} of {r[6]} detections, mean {100 * r[7]:.1f} cm, "
            f"worst {100 * r[8]:.1f} cm",
            end="",
        )
    benchmark.extra_info["rows"] = rows
