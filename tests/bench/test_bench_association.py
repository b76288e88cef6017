"""Association of landmarks that look alike: cost per landmark per movement, and issue 11's
goals on the real simulator (not in the default run: ``pytest tests/bench``).

``test_association_scaling``: the joint estimator plus association over 20 synthetic movements
(no images) with 4, 8, 16 and 32 identical landmarks and a distinct reference pair; the
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

from pipeline.association import Associator
from pipeline.estimators import make_estimator
from pipeline.joint.geometry import MovementPose
from pipeline.slam import MovementObservation
from pipeline.synthetic import simulate_bearings

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "replay"))
from alike_scenarios import ARENA_M, REFERENCE_M, alike_scenario
from alike_scoring import score_log

EPS = math.radians(3.0)
MOVES = 20


def _layout(n: int, rng: np.random.Generator) -> dict[str, tuple[float, float]]:
    lms = {"L1": REFERENCE_M[0], "L2": REFERENCE_M[1]}
    while len(lms) < n + 2:
        p = (float(rng.uniform(0.1, ARENA_M[0] - 0.1)), float(rng.uniform(0.1, ARENA_M[1] - 0.1)))
        if all(math.dist(p, q) >= 0.15 for q in lms.values()):
            lms[f"B{len(lms) - 1}"] = p
    return lms


def _run(n: int, seed: int, *, associate: bool) -> float:
    """Seconds for the estimator (and association) over one synthetic run."""
    rng = np.random.default_rng(seed)
    lms = _layout(n, rng)
    sim = simulate_bearings(
        MOVES, rng, landmarks_world=lms, arena_m=ARENA_M, move_m=(0.2, 0.4), clearance_m=0.08
    )
    assoc = Associator({"blue": n}, ("L1", "L2"), vision_error_rad=EPS)
    names = ["L1", "L2", *(assoc.names if associate else [k for k in lms if k[0] == "B"])]
    slam = make_estimator("joint", names, ("L1", "L2"), vision_error_rad=EPS, rng=rng)
    tick = time.perf_counter()
    for obs in sim.observations:
        if not associate:
            slam.process_movement(obs)
            continue
        ends = (obs.bearings_o1_rad, obs.bearings_o2_rad)
        unique = tuple({k: v for k, v in b.items() if k[0] == "L"} for b in ends)
        blobs = tuple({"blue": [v for k, v in b.items() if k[0] == "B"]} for b in ends)
        a = assoc.associate(obs.index, (unique[0], unique[1]), (blobs[0], blobs[1]), slam.estimates)
        res = slam.process_movement(
            MovementObservation(
                obs.index,
                {**unique[0], **a.bearings_o1_rad},
                {**unique[1], **a.bearings_o2_rad},
            )
        )
        pose = None
        if res.status == "ok" and res.o1_fl is not None and res.o2_fl is not None:
            o1, o2 = res.o1_fl.mean(axis=0), res.o2_fl.mean(axis=0)
            d = o2 - o1
            pose = MovementPose(o1, math.atan2(d[1], d[0]), float(np.hypot(*d)))
        assoc.hypothesize(a, pose, slam.estimates)
        for name, hist in a.history.items():
            slam.add_history(name, hist)  # type: ignore[attr-defined]
    return time.perf_counter() - tick


@pytest.mark.parametrize("n", [4, 8, 16, 32])
def test_association_scaling(benchmark: Any, n: int) -> None:
    with_assoc: list[float] = []
    without: list[float] = []

    def once() -> None:
        seed = len(with_assoc)
        with_assoc.append(_run(n, seed, associate=True))
        without.append(_run(n, seed, associate=False))

    benchmark.pedantic(once, rounds=3, iterations=1)
    per = 1000.0 * float(np.median(with_assoc)) / MOVES / n
    benchmark.extra_info["ms_per_landmark_per_movement"] = per
    benchmark.extra_info["yardstick_ms_per_landmark_per_movement"] = (
        1000.0 * float(np.median(without)) / MOVES / n
    )
    print(f"\n{n} landmarks: {per:.2f} ms per landmark per movement (estimator + association)")


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
