"""Association of landmarks that look alike: cost per landmark per movement, and issue 11's
goals on the real simulator (not in the default run: ``pytest tests/bench``).

``test_association_scaling``: the joint estimator plus association over 20 synthetic movements
(no images) with 4, 8, 16 and 32 identical landmarks and a distinct reference pair, and the
time spent in association alone (``Associator.associate`` and ``hypothesize``), and the
association of every keyframe with the final map once the run is over; the
yardstick (the same run with every landmark of its own class, so no association) is measured
in the same run, alternated; and what each landmark added between consecutive sizes costs per
movement. ``test_matching_cost``: placing one movement by matching its detections with the
map, against placing it from the same detections identified. ``test_association_goals``: 8
identical landmarks, 10 seeds per camera model, scored like
``tests/replay/test_association_sim.py``; the figures are printed and kept in ``extra_info``
(docs/RESULTS.md).
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
from pipeline.fusion import PAPER_N_L, PAPER_N_R
from pipeline.joint.window import DEFAULT_WINDOW
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
    slam = make_estimator(
        "joint",
        list(lms),
        ("L1", "L2"),
        vision_error_rad=EPS,
        rng=rng,
        prior="impartial",
        n_r=PAPER_N_R,
        n_l=PAPER_N_L,
        turn_prior_sigma_rad=None,
        distance_prior_rel=None,
        window=DEFAULT_WINDOW,
    )
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
    repair: dict[int, list[float]] = {n: [] for n in SIZES}
    without: dict[int, list[float]] = {n: [] for n in SIZES}

    def once() -> None:
        seed = len(with_assoc[SIZES[0]])
        for n in SIZES:
            run = run_synthetic(n, seed, moves=MOVES)
            with_assoc[n].append(run.seconds)
            assoc_only[n].append(run.association_seconds)
            final[n].append(run.final_seconds)
            repair[n].append(run.repair_seconds)
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
        repair_ms = 1000.0 * float(np.median(repair[n]))
        print(f", its repair's search: {repair_ms:.1f} ms", end="")
        benchmark.extra_info[f"final_repair_ms_per_run_{n}"] = repair_ms
    for label, ms in (("estimator + association", per_move), ("yardstick", yard_move)):
        steps = []
        for a, b in itertools.pairwise(SIZES):
            added = (ms[b] - ms[a]) / (b - a)
            benchmark.extra_info[f"{label} ms_per_added_landmark_{a}_{b}"] = added
            steps.append(f"{a}->{b} {added:.2f}")
        print(f"\n{label}: ms per added landmark per movement {', '.join(steps)}", end="")


def _matching_case(
    n: int, rng: np.random.Generator
) -> tuple[np.ndarray, list[str], tuple[dict[str, list[float]], dict[str, list[float]]], Any]:
    """A map of ``n`` identical landmarks and the reference pair, and one movement's
    detections (3/4 of the landmarks at each keyframe, 1 degree of noise) with their true
    identities as sightings (FL)."""
    from pipeline.geometry import Sightings

    pts = np.vstack(([[0.0, 0.0], [1.0, 0.0]], rng.uniform((-1, -1), (2, 1), (n, 2))))
    labels = ["L1", "L2"] + ["blue"] * n
    o1 = rng.uniform((-0.8, -0.8), (1.8, 0.8))
    h = rng.uniform(-math.pi, math.pi)
    o2 = o1 + rng.uniform(0.2, 0.8) * np.array([math.cos(h), math.sin(h)])
    dets: list[dict[str, list[float]]] = [{}, {}]
    seen_pts, seen_end, seen_b = [], [], []
    for end, o in enumerate((o1, o2)):
        d = pts - o
        b = np.arctan2(d[:, 1], d[:, 0]) - h + rng.normal(0.0, math.radians(1.0), len(pts))
        b = np.angle(np.exp(1j * b))
        for k in np.flatnonzero(rng.random(len(pts)) < 0.75):
            dets[end].setdefault(labels[k], []).append(float(b[k]))
            seen_pts.append(pts[k])
            seen_end.append(end)
            seen_b.append(float(b[k]))
    s = Sightings(np.array(seen_pts), np.array(seen_end, np.int64), np.array(seen_b))
    return pts, labels, (dets[0], dets[1]), (s, o1)


def test_matching_cost(benchmark: Any) -> None:
    """Placing one movement by matching its detections with the map
    (:func:`pipeline.association.match.match_movement`, used only when too few are identified)
    at 4, 8, 16 and 32 identical landmarks, against the yardstick of placing it from the
    same detections identified (:func:`pipeline.geometry.resect` from the known O1),
    alternated call by call; medians and their ratio per size."""
    from pipeline.association.match import match_movement
    from pipeline.geometry import resect

    cases = {
        n: [_matching_case(n, np.random.default_rng(100 + k)) for k in range(15)] for n in SIZES
    }
    matching: dict[int, list[float]] = {n: [] for n in SIZES}
    identified: dict[int, list[float]] = {n: [] for n in SIZES}

    def once() -> None:
        for n in SIZES:
            for pts, labels, dets, (s, o1) in cases[n]:
                tick = time.perf_counter()
                match_movement(pts, labels, dets, o1, 0, EPS)
                matching[n].append(time.perf_counter() - tick)
                tick = time.perf_counter()
                resect(s, guesses=[], o1_known_fl=o1)
                identified[n].append(time.perf_counter() - tick)

    benchmark.pedantic(once, rounds=3, iterations=1)
    for n in SIZES:
        m, y = (1000.0 * float(np.median(v[n])) for v in (matching, identified))
        print(
            f"\n{n} landmarks: matching {m:.1f} ms per movement ({m / (n + 2):.2f} per landmark), "
            f"{m / y:.1f} times the identified placement ({y:.2f} ms)",
            end="",
        )
        benchmark.extra_info[f"matching_ms_{n}"] = m
        benchmark.extra_info[f"matching_over_identified_{n}"] = m / y


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
