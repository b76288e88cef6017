"""Association of landmarks that look alike: cost per landmark per movement, and issue 11's
goals on the real simulator (not in the default run: ``pytest tests/bench``).

``test_association_scaling``: the joint estimator plus association over 20 synthetic movements
(no images) with 4, 8, 16 and 32 identical landmarks and a distinct reference pair, and the
time spent in association alone (``Associator.associate`` and ``hypothesize``), and the
association of every keyframe with the final map once the run is over; the
yardstick (the same run with every landmark of its own class, so no association) is measured
in the same run, alternated; and what each landmark added between consecutive sizes costs per
movement. ``test_association_goals``: 8 identical landmarks, 10 seeds per camera model, scored
like ``tests/replay/test_association_sim.py``; the figures are printed and kept in
``extra_info`` (docs/RESULTS.md).
"""

from __future__ import annotations

import itertools
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

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


SIZES = (4, 8, 16, 32)


def test_association_scaling(benchmark: Any) -> None:
    """Per round, every size in turn, each run followed by its yardstick; then, per size, the
    medians per landmark per movement, and between consecutive sizes what each added landmark
    costs per movement (the difference of the medians per movement over the landmarks added:
    the cost of a movement that does not depend on the landmarks cancels out)."""
    with_assoc: dict[int, list[float]] = {n: [] for n in SIZES}
    assoc_only: dict[int, list[float]] = {n: [] for n in SIZES}
    final: dict[int, list[float]] = {n: [] for n in SIZES}
    without: dict[int, list[float]] = {n: [] for n in SIZES}

    def once() -> None:
        seed = len(with_assoc[SIZES[0]])
        for n in SIZES:
            run = run_synthetic(n, seed, moves=MOVES)
            with_assoc[n].append(run.seconds)
            assoc_only[n].append(run.association_seconds)
            final[n].append(run.final_seconds)
            without[n].append(_yardstick(n, seed))

    benchmark.pedantic(once, rounds=7, iterations=1)
    per_move = {n: 1000.0 * float(np.median(with_assoc[n])) / MOVES for n in SIZES}
    yard_move = {n: 1000.0 * float(np.median(without[n])) / MOVES for n in SIZES}
    for n in SIZES:
        own = 1000.0 * float(np.median(assoc_only[n])) / MOVES / n
        print(
            f"\n{n} landmarks: {per_move[n] / n:.2f} ms per landmark per movement (estimator + "
            f"association), association alone {own:.2f}; yardstick (joint estimator, landmarks "
            f"distinct) {yard_move[n] / n:.2f}",
            end="",
        )
        benchmark.extra_info[f"ms_per_landmark_per_movement_{n}"] = per_move[n] / n
        benchmark.extra_info[f"association_ms_per_landmark_per_movement_{n}"] = own
        benchmark.extra_info[f"yardstick_ms_per_landmark_per_movement_{n}"] = yard_move[n] / n
        once_ms = 1000.0 * float(np.median(final[n]))
        print(f"; the final map's association, once per run: {once_ms:.1f} ms", end="")
        benchmark.extra_info[f"final_association_ms_per_run_{n}"] = once_ms
    for label, ms in (("estimator + association", per_move), ("yardstick", yard_move)):
        steps = []
        for a, b in itertools.pairwise(SIZES):
            added = (ms[b] - ms[a]) / (b - a)
            benchmark.extra_info[f"{label} ms_per_added_landmark_{a}_{b}"] = added
            steps.append(f"{a}->{b} {added:.2f}")
        print(f"\n{label}: ms per added landmark per movement {', '.join(steps)}", end="")


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
                        s.n_final_correct,
                        s.n_final_named,
                    )
                )

    benchmark.pedantic(once, rounds=1, iterations=1)
    for r in rows:
        print(
            f"\n{r[0]:9s} seed {r[1]:2d}: named {r[2]}/8 (distinct truths {r[3]}), "
            f"correct {r[4]}/{r[5]} of {r[6]} detections (with the final map {r[9]}/{r[10]}), "
            f"mean {100 * r[7]:.1f} cm, worst {100 * r[8]:.1f} cm",
            end="",
        )
    benchmark.extra_info["rows"] = rows
