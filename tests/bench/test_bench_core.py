"""Benchmarks of the estimation core (not in the default run: ``pytest tests/bench``).

Each group has a yardstick measured in the same run (a plain numpy op of the same size);
compare medians. Peak memory of the chunked exact change of frame is in ``extra_info``.
"""

from __future__ import annotations

import math
import statistics
import time
import tracemalloc
from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np
import pytest

from pipeline import BearingSlam, ConeIntersection, intersect_cones
from pipeline.frame_change import change_frame_exact, change_frame_sampled, to_fl
from pipeline.fusion import PROPOSALS_PER_PARTICLE, fuse, fuse_likelihood
from pipeline.init_fr import sample_fr_posterior
from pipeline.likelihood import N_FRAMES, FrameLikelihood
from pipeline.priors import ImpartialPrior
from pipeline.synthetic import PAPER_REFERENCE, simulate_bearings

EPS = math.radians(3.0)
#: Alternated rounds of the growth benchmark.
ROUNDS = 41


def _sets(n_r: int) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    rng = np.random.default_rng(0)
    return (
        rng.normal([2.0, 3.0], 0.2, (n_r, 2)),
        rng.normal([4.0, 3.5], 0.2, (n_r, 2)),
        {"L3": rng.normal([1.0, 1.0], 0.3, (n_r, 2))},
    )


@pytest.mark.benchmark(group="yardstick")
def test_yardstick_exp_100k(benchmark: Any) -> None:
    x = np.random.default_rng(0).random(100_000)
    benchmark(np.exp, x)


@pytest.mark.benchmark(group="frame_change")
@pytest.mark.parametrize("n_r", [50, 100, 200])
def test_frame_change_exact(benchmark: Any, n_r: int) -> None:
    s1, s2, others = _sets(n_r)
    rng = np.random.default_rng(1)
    tracemalloc.start()
    change_frame_exact(s1, s2, others, 300, rng)
    benchmark.extra_info["peak_mib"] = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    benchmark(change_frame_exact, s1, s2, others, 300, rng)


@pytest.mark.benchmark(group="frame_change")
def test_frame_change_sampled(benchmark: Any) -> None:
    s1, s2, others = _sets(50)
    benchmark(change_frame_sampled, s1, s2, others, 300, np.random.default_rng(1))


@pytest.mark.benchmark(group="pdf")
def test_impartial_pdf_100k(benchmark: Any) -> None:
    rng = np.random.default_rng(2)
    prior = ImpartialPrior(EPS)
    # points around a cone: a quarter inside it
    r = rng.uniform(0.1, 20.0, 100_000)
    a = 0.2 + rng.uniform(-4 * EPS, 4 * EPS, 100_000)
    pts = np.column_stack((r * np.cos(a), r * np.sin(a)))
    benchmark(prior.density, pts, np.zeros(2), 0.2)


def _likelihood_case() -> tuple[np.ndarray, np.ndarray, tuple[float, float], np.ndarray]:
    """Reference pools (1024 FR particles each), L3's bearings and a 4800-point belief in FL."""
    rng = np.random.default_rng(3)
    prior = ImpartialPrior(EPS)
    truth_fr = {"L1": np.array([1.5, 2.0]), "L2": np.array([2.6, 1.4]), "L3": np.array([0.5, 1.2])}
    bearings = {
        k: (math.atan2(v[1], v[0]), math.atan2(v[1], v[0] - 1.0)) for k, v in truth_fr.items()
    }
    pools = []
    for ref in ("L1", "L2"):
        region = intersect_cones(*bearings[ref], EPS, prior.r_min, prior.r_max)
        assert isinstance(region, ConeIntersection)
        pool = sample_fr_posterior(region, prior, prior, 1024, rng)
        assert isinstance(pool, np.ndarray)
        pools.append(pool)
    centre = to_fl(truth_fr["L3"], truth_fr["L1"], truth_fr["L2"])
    prev = rng.multivariate_normal(centre, np.diag([0.01, 0.004]), 4800)
    return pools[0], pools[1], bearings["L3"], prev


@pytest.mark.benchmark(group="fusion")
def test_likelihood_fusion_step(benchmark: Any) -> None:
    """The default fusion of one landmark: 4800 proposals x 16 frame pairs of 1024 x 1024."""
    pool1, pool2, (b1, b2), prev = _likelihood_case()
    rng = np.random.default_rng(4)
    frame = FrameLikelihood(pool1, pool2, ImpartialPrior(EPS))  # once per movement
    lik = partial(frame, bearing_o1_rad=b1, bearing_o2_rad=b2, rng=rng)
    assert fuse_likelihood(prev, lik, 300, rng) is not None
    benchmark(fuse_likelihood, prev, lik, 300, rng, prev_weights=np.ones(4800))


@pytest.mark.benchmark(group="fusion")
def test_likelihood_fusion_step_defensive(benchmark: Any) -> None:
    """A wide belief (sd 0.5) around a narrow likelihood: plain draws + 4800 defensive draws."""
    pool1, pool2, (b1, b2), prev = _likelihood_case()
    rng = np.random.default_rng(4)
    frame = FrameLikelihood(pool1, pool2, ImpartialPrior(EPS))
    lik = partial(frame, bearing_o1_rad=b1, bearing_o2_rad=b2, rng=rng)
    centre = prev.mean(axis=0)
    wide = rng.normal(centre + 0.5, 0.5, (300, 2))
    new_fl = rng.normal(centre, 0.1, (300, 2))
    res = fuse_likelihood(wide, lik, 300, rng, new_fl=new_fl)
    assert res is not None and res.defensive
    benchmark(fuse_likelihood, wide, lik, 300, rng, new_fl=new_fl)


@pytest.mark.benchmark(group="fusion")
def test_likelihood_frame_per_movement(benchmark: Any) -> None:
    """What a movement pays once for all its landmarks: sorting the two 1024-particle pools."""
    pool1, pool2, _, _ = _likelihood_case()
    benchmark(FrameLikelihood, pool1, pool2, ImpartialPrior(EPS))


@pytest.mark.benchmark(group="fusion")
def test_yardstick_exp_77k(benchmark: Any) -> None:
    x = np.random.default_rng(0).random(4800 * 16)  # the (proposal, frame) pairs of one step
    benchmark(np.exp, x)


@pytest.mark.benchmark(group="fusion")
def test_product_fusion_step(benchmark: Any) -> None:
    """The paper's product of two 300-particle KDEs (``fusion="product"``)."""
    rng = np.random.default_rng(3)
    a = rng.multivariate_normal([0.0, 0.0], np.diag([0.04, 0.01]), 300)
    b = rng.multivariate_normal([0.1, 0.0], np.diag([0.01, 0.04]), 300)
    benchmark(fuse, a, b, 300, rng)


@pytest.mark.benchmark(group="fusion")
def test_yardstick_exp_180k(benchmark: Any) -> None:
    x = np.random.default_rng(0).random(180_000)  # the kernel evaluations of one fusion step
    benchmark(np.exp, x)


@pytest.mark.benchmark(group="run")
def test_whole_run_10_movements(benchmark: Any) -> None:
    run = simulate_bearings(10, np.random.default_rng(4), eps_rad=EPS)

    def go() -> None:
        slam = BearingSlam(
            ["L1", "L2", "L3", "L4"],
            PAPER_REFERENCE,
            vision_error_rad=EPS,
            rng=np.random.default_rng(5),
        )
        for obs in run.observations:
            slam.process_movement(obs)

    benchmark(go)


def _alternate(step: Callable[[], object], yardstick: Callable[[], object]) -> tuple[float, float]:
    """Medians (s) of ``step`` and ``yardstick``, timed one after the other ``ROUNDS`` times."""
    a, b = [], []
    for _ in range(ROUNDS):
        t0 = time.perf_counter()
        step()
        t1 = time.perf_counter()
        yardstick()
        t2 = time.perf_counter()
        a.append(t1 - t0)
        b.append(t2 - t1)
    return statistics.median(a), statistics.median(b)


@pytest.mark.parametrize("defensive", [False, True], ids=["plain", "defensive"])
@pytest.mark.benchmark(group="fusion_growth")
def test_fusion_step_grows_like_n_l(benchmark: Any, defensive: bool) -> None:
    """The step at n_l = 75-1200 against ``np.exp`` of its (proposal, frame) pair count,
    alternated: a flat ratio (and cost per particle) as n_l doubles is linear growth. Plain: a
    belief covering the likelihood; defensive: a wide belief around a narrow likelihood (the
    mixture's draws and its two KDE densities of n_l kernels each, where L_t > 0)."""
    pool1, pool2, (b1, b2), belief = _likelihood_case()
    frame = FrameLikelihood(pool1, pool2, ImpartialPrior(EPS))
    centre = belief.mean(axis=0)
    rng = np.random.default_rng(4)
    lik = partial(frame, bearing_o1_rad=b1, bearing_o2_rad=b2, rng=rng)
    rows = []
    for n_l in (75, 150, 300, 600, 1200):
        m = PROPOSALS_PER_PARTICLE * n_l
        if defensive:
            prev = rng.normal(centre + 0.5, 0.5, (n_l, 2))
            new_fl: np.ndarray | None = rng.normal(centre, 0.1, (n_l, 2))
        else:
            prev = rng.multivariate_normal(centre, np.diag([0.01, 0.004]), m)
            new_fl = None
        res = fuse_likelihood(prev, lik, n_l, rng, new_fl=new_fl)
        assert res is not None and res.defensive == defensive
        values = np.random.default_rng(0).random(m * N_FRAMES)
        step_s, yard_s = _alternate(
            partial(fuse_likelihood, prev, lik, n_l, rng, new_fl=new_fl),
            partial(np.exp, values),
        )
        rows.append((n_l, step_s, yard_s))
        benchmark.extra_info[f"n_l={n_l}"] = {
            "step_ms": step_s * 1e3,
            "yardstick_ms": yard_s * 1e3,
            "ratio": step_s / yard_s,
            "us_per_particle": step_s * 1e6 / n_l,
        }
    print(f"\n{'defensive' if defensive else 'plain'} step (medians of {ROUNDS}, alternated):")
    for n_l, step_s, yard_s in rows:
        print(
            f"  n_l {n_l:5d}: {step_s * 1e3:7.3f} ms, {step_s * 1e6 / n_l:6.2f} us/particle, "
            f"{step_s / yard_s:5.1f}x np.exp of {PROPOSALS_PER_PARTICLE * N_FRAMES * n_l}"
        )
    benchmark.pedantic(lambda: None, rounds=1)  # the figures above are the result
