"""Benchmark: the joint estimator over long runs (issue 31), not in the default run.

Synthetic bearings (no images), every movement with its driven distance (2% noise) and the
distance prior ``process`` uses. CPU time (``time.process_time``) per movement of
``JointSlam.process_movement``, with its default window of 100 movements (older ones
marginalized, ``pipeline/joint/window.py``) unless said otherwise.

``test_marginal_cost_late_against_early``: 1,000 movements on the paper arena (4 landmarks) and
on a 16-landmark arena (3 x 2 m); the yardstick is the same run early: the median CPU per
movement over movements 500-999 against that over movements 50-99. Goal: at most 1.3x. The
means (which count the rebuild of the graph every 50 movements) are printed beside.

``test_window_against_whole_map``: the same runs (600 movements, two seeds per arena) with the
window and keeping every movement (``window=None``), alternated: CPU of the whole run and the
mean error of the final map against the truth.

``test_update_against_plain_isam2``: per movement, the estimator's own work (its whole
``process_movement`` less the paper filter it runs as initializer) against a plain iSAM2 (GTSAM's
default parameters, one ``update()`` per update of the estimator, nothing else computed) given the
same factors and initial values, the two alternated movement by movement. Goal: medians at most
3x.

``test_estimator_and_association_late_at_32_landmarks``: association of 32 identical landmarks
with the estimator, 300 movements; CPU per landmark per movement late (200-299). Goal: at most 1 ms.

``test_growth_law``: the CPU per movement against movements and landmarks (4, 8, 16, 32
landmarks, 1,000 movements each, with the window and keeping every movement), written with a
plot to ``$BSLAM_BENCH_OUT`` (default: a temporary folder) as ``growth.json`` and
``growth.png`` (docs/benchmarks.md).

Run with ``python -m pytest tests/bench/test_bench_growth.py -s -n 0``.
"""

from __future__ import annotations

import json
import math
import os
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import gtsam
import numpy as np
import pytest
from bench_runs import scattered_run, with_distances

from pipeline.joint.estimator import JointSlam
from pipeline.joint.mapgraph import MapGraph
from pipeline.joint.state import JointSettings
from pipeline.joint.window import DEFAULT_WINDOW
from pipeline.slam import MovementObservation
from pipeline.synthetic import PAPER_REFERENCE, SimulatedRun, simulate_bearings

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "pipeline"))
from alike_synthetic import run_synthetic

EPS = math.radians(3.0)
DISTANCE_PRIOR_REL = 0.05  # replay's default (pipeline.estimators.DEFAULT_DISTANCE_PRIOR_REL)


def _run(n_movements: int, n_landmarks: int, seed: int) -> SimulatedRun:
    """A simulated run with each movement's driven distance (true length, 2% noise)."""
    rng = np.random.default_rng(seed)
    if n_landmarks == 4:
        run = simulate_bearings(n_movements, rng, eps_rad=EPS)
    else:
        run = scattered_run(n_movements, n_landmarks, rng, EPS, 0.12)
    return with_distances(run, rng)


def _slam(run: SimulatedRun, seed: int, window: int | None = DEFAULT_WINDOW) -> JointSlam:
    return JointSlam(
        list(run.landmarks_world),
        PAPER_REFERENCE,
        vision_error_rad=EPS,
        rng=np.random.default_rng(seed),
        distance_prior_rel=DISTANCE_PRIOR_REL,
        window=window,
    )


def _cpu_per_movement(
    run: SimulatedRun, seed: int, window: int | None = DEFAULT_WINDOW
) -> tuple[list[float], float]:
    """CPU seconds of each movement, and the mean error of the final map (FL)."""
    slam = _slam(run, seed, window)
    spent = []
    for obs in run.observations:
        tick = time.process_time()
        slam.process_movement(obs)
        spent.append(time.process_time() - tick)
    truth = run.truth_fl()
    err = [float(np.hypot(*(e.mean_fl - truth[n]))) for n, e in slam.estimates.items()]
    return spent, float(np.mean(err))


def _out_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = os.environ.get("BSLAM_BENCH_OUT")
    path = Path(out) if out else tmp_path_factory.mktemp("growth")
    path.mkdir(parents=True, exist_ok=True)
    return path


@pytest.mark.parametrize("n_landmarks", [4, 16])
def test_marginal_cost_late_against_early(n_landmarks: int, benchmark: Any) -> None:
    spent, err = _cpu_per_movement(_run(1000, n_landmarks, 1), 1)
    early = statistics.median(spent[50:100])
    late = statistics.median(spent[500:1000])
    ratio = late / early
    mean_early, mean_late = statistics.mean(spent[50:100]), statistics.mean(spent[500:1000])
    print(
        f"\n{n_landmarks} landmarks: CPU per movement early (50-99) {1e3 * early:.2f} ms, "
        f"late (500-999) {1e3 * late:.2f} ms, ratio {ratio:.2f} (goal 1.3); means "
        f"{1e3 * mean_early:.2f} and {1e3 * mean_late:.2f} ms, ratio {mean_late / mean_early:.2f}; "
        f"mean error of the final map {err:.4f} FL"
    )
    benchmark.extra_info.update(
        early_ms=1e3 * early,
        late_ms=1e3 * late,
        ratio=ratio,
        mean_early_ms=1e3 * mean_early,
        mean_late_ms=1e3 * mean_late,
    )
    benchmark.pedantic(lambda: None, rounds=1, iterations=1)
    assert ratio <= 1.3


@pytest.mark.parametrize("n_landmarks", [4, 16])
def test_window_against_whole_map(n_landmarks: int, benchmark: Any) -> None:
    cpu: dict[str, list[float]] = {"window": [], "whole": []}
    err: dict[str, list[float]] = {"window": [], "whole": []}
    for seed in (4, 5):
        run = _run(600, n_landmarks, seed)
        for label, window in (("window", DEFAULT_WINDOW), ("whole", None)):
            spent, e = _cpu_per_movement(run, seed, window)
            cpu[label].append(sum(spent))
            err[label].append(e)
    for label in cpu:
        print(
            f"\n{n_landmarks} landmarks, {label}: whole run {statistics.median(cpu[label]):.1f} s "
            f"CPU (seeds 4, 5: {', '.join(f'{c:.1f}' for c in cpu[label])}), mean error of the "
            f"final map {', '.join(f'{e:.4f}' for e in err[label])} FL",
            end="",
        )
    benchmark.extra_info.update(cpu_s=cpu, mean_error_fl=err)
    benchmark.pedantic(lambda: None, rounds=1, iterations=1)


def test_estimator_and_association_late_at_32_landmarks(benchmark: Any) -> None:
    """32 identical landmarks and a distinct reference pair, every name given by association
    (``tests/pipeline/alike_synthetic.py``), 300 movements: CPU per landmark per movement of
    association plus the estimator, medians over movements 50-99 and 200-299."""
    run = run_synthetic(32, 0, moves=300)
    spent = run.movement_cpu_seconds
    early = 1e3 * statistics.median(spent[50:100]) / 32
    late = 1e3 * statistics.median(spent[200:300]) / 32
    print(
        f"\n32 landmarks: estimator + association {early:.2f} ms per landmark per movement at "
        f"movements 50-99, {late:.2f} at 200-299 (goal 1); "
        f"mean {1e3 * statistics.mean(spent[200:300]) / 32:.2f}"
    )
    benchmark.extra_info.update(early_ms_per_landmark=early, late_ms_per_landmark=late)
    benchmark.pedantic(lambda: None, rounds=1, iterations=1)
    assert late <= 1.0


class _RecordingGraph(MapGraph):
    """The joint map's graph, with every iSAM2 update it makes replayed into a plain iSAM2 right
    after (the plain one timed apart)."""

    def __init__(self, settings: JointSettings) -> None:
        self.plain_s = 0.0
        self._plain = gtsam.ISAM2()
        super().__init__(settings)

    def new_isam(self, n_placed: int) -> gtsam.ISAM2:
        self._plain = gtsam.ISAM2()
        return super().new_isam(n_placed)

    def update(
        self,
        graph: gtsam.NonlinearFactorGraph,
        values: gtsam.Values,
        remove: Any = (),
    ) -> None:
        super().update(graph, values, remove)
        tick = time.process_time()
        self._plain.update(graph, values, list(remove))
        self.plain_s += time.process_time() - tick


@pytest.mark.parametrize(("n_landmarks", "n_movements"), [(4, 300), (16, 200)])
def test_update_against_plain_isam2(n_landmarks: int, n_movements: int, benchmark: Any) -> None:
    run = _run(n_movements, n_landmarks, 2)
    slam = JointSlam(
        list(run.landmarks_world),
        PAPER_REFERENCE,
        vision_error_rad=EPS,
        rng=np.random.default_rng(2),
        distance_prior_rel=DISTANCE_PRIOR_REL,
    )
    recorded = slam._map = _RecordingGraph(slam.settings)  # before any movement
    paper: list[float] = []
    inner = slam.paper.process_movement

    def timed(obs: MovementObservation) -> Any:
        tick = time.process_time()
        out = inner(obs)
        paper.append(time.process_time() - tick)
        return out

    slam.paper.process_movement = timed  # type: ignore[method-assign]
    own, plain = [], []
    for obs in run.observations:
        before = recorded.plain_s
        tick = time.process_time()
        slam.process_movement(obs)
        total = time.process_time() - tick
        plain.append(recorded.plain_s - before)
        own.append(total - (recorded.plain_s - before) - paper[-1])
    m_own, m_plain = statistics.median(own[20:]), statistics.median(plain[20:])
    ratio = m_own / m_plain
    print(
        f"\n{n_landmarks} landmarks, {n_movements} movements: estimator update per movement "
        f"{1e3 * m_own:.2f} ms, plain iSAM2 on the same factors {1e3 * m_plain:.2f} ms, "
        f"ratio {ratio:.2f} (goal 3); paper filter {1e3 * statistics.median(paper):.2f} ms"
    )
    benchmark.extra_info.update(own_ms=1e3 * m_own, plain_ms=1e3 * m_plain, ratio=ratio)
    benchmark.pedantic(lambda: None, rounds=1, iterations=1)
    assert ratio <= 3.0


WINDOWS = ((50, 100), (200, 300), (500, 1000))


def test_growth_law(tmp_path_factory: pytest.TempPathFactory, benchmark: Any) -> None:
    out = _out_dir(tmp_path_factory)
    table: dict[str, Any] = {}
    for n_landmarks in (4, 8, 16, 32):
        run = _run(1000, n_landmarks, 3)
        for label, window in (("window", DEFAULT_WINDOW), ("whole", None)):
            spent, err = _cpu_per_movement(run, 3, window)
            row = table[f"{n_landmarks} {label}"] = {
                "cpu_ms": [1e3 * s for s in spent],
                "median_ms": {
                    f"{a}-{b - 1}": 1e3 * statistics.median(spent[a:b]) for a, b in WINDOWS
                },
                "mean_ms": {f"{a}-{b - 1}": 1e3 * statistics.mean(spent[a:b]) for a, b in WINDOWS},
                "whole_run_s": sum(spent),
                "mean_error_fl": err,
            }
            print(
                f"\n{n_landmarks} landmarks, {label}: medians {row['median_ms']}, means "
                f"{row['mean_ms']}, whole run {sum(spent):.1f} s, error {err:.4f}"
            )
    (out / "growth.json").write_text(json.dumps(table) + "\n")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3.6), dpi=100)
    colours = {n: f"C{i}" for i, n in enumerate(("4", "8", "16", "32"))}
    for name, row in table.items():
        size, label = name.split()
        ms = np.array(row["cpu_ms"])
        k = 50  # running median over 50 movements
        smooth = [float(np.median(ms[i : i + k])) for i in range(0, ms.size - k + 1, 10)]
        ax.plot(
            np.arange(len(smooth)) * 10 + k / 2,
            smooth,
            color=colours[size],
            linestyle="-" if label == "window" else ":",
            label=f"{size} landmarks" + ("" if label == "window" else ", every movement"),
        )
    ax.set_xlabel("movement")
    ax.set_ylabel("CPU per movement (ms, median of 50)")
    ax.set_yscale("log")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(out / "growth.png")
    print(f"written {out / 'growth.json'}, {out / 'growth.png'}")
    benchmark.pedantic(lambda: None, rounds=1, iterations=1)
