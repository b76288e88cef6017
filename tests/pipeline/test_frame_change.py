"""Change of frame FR -> FL and systematic resampling (docs/method.md, part 4)."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from pipeline.frame_change import change_frame_exact, change_frame_sampled, to_fl
from pipeline.resample import systematic_resample

seed_s = st.integers(0, 2**32 - 1)
coef_s = st.tuples(
    st.floats(0.1, 10.0), st.floats(-np.pi, np.pi), st.floats(-50, 50), st.floats(-50, 50)
)


def _sets(seed: int, n: int = 20) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    rng = np.random.default_rng(seed)
    s1 = rng.normal([2.0, 3.0], 0.2, (n, 2))
    s2 = rng.normal([4.0, 3.5], 0.2, (n, 2))
    return s1, s2, {"L3": rng.normal([1.0, 1.0], 0.3, (n, 2))}


@given(seed_s)
def test_reference_pair_goes_exactly_to_the_frame_points(seed: int) -> None:
    s1, s2, _ = _sets(seed)
    assert np.array_equal(to_fl(s1, s1, s2), np.zeros_like(s1))
    assert np.array_equal(to_fl(s2, s1, s2), np.tile([1.0, 0.0], (s1.shape[0], 1)))


@given(seed_s, coef_s, st.sampled_from(["sampled", "exact"]))
def test_change_of_frame_commutes_with_similarities(
    seed: int, coef: tuple[float, float, float, float], method: str
) -> None:
    scale, angle, tx, ty = coef
    s1, s2, others = _sets(seed)
    c, s = scale * np.cos(angle), scale * np.sin(angle)

    def sim(p: np.ndarray) -> np.ndarray:
        return np.column_stack((c * p[:, 0] - s * p[:, 1] + tx, s * p[:, 0] + c * p[:, 1] + ty))

    fn = change_frame_exact if method == "exact" else change_frame_sampled
    a = fn(s1, s2, others, 100, np.random.default_rng(seed))
    b = fn(
        sim(s1), sim(s2), {k: sim(v) for k, v in others.items()}, 100, np.random.default_rng(seed)
    )
    # landmarks' FL sets do not depend on the FR frame (O1, O2 are pinned to FR by definition)
    np.testing.assert_allclose(b.landmarks_fl["L3"], a.landmarks_fl["L3"], atol=1e-9)


def test_exact_enumerates_every_pair_and_chunks_do_not_change_it() -> None:
    s1, s2, others = _sets(3, n=12)
    full = change_frame_exact(s1, s2, others, 300, np.random.default_rng(0), chunk_elems=10**9)
    small = change_frame_exact(s1, s2, others, 300, np.random.default_rng(0), chunk_elems=50)
    assert full.o1_fl.shape == (144, 2)
    np.testing.assert_array_equal(full.landmarks_fl["L3"], small.landmarks_fl["L3"])
    # every kept particle is one of the n^3 triples
    triples = to_fl(others["L3"][None, None, :, :], s1[:, None, None, :], s2[None, :, None, :])
    flat = triples.reshape(-1, 2)
    for p in full.landmarks_fl["L3"][:20]:
        assert np.min(np.abs(flat - p).sum(axis=1)) == 0.0


def test_exact_and_sampled_agree_in_distribution() -> None:
    s1, s2, others = _sets(5, n=50)
    ex = change_frame_exact(s1, s2, others, 20_000, np.random.default_rng(1))
    sa = change_frame_sampled(s1, s2, others, 20_000, np.random.default_rng(2))
    triples = to_fl(others["L3"][None, None, :, :], s1[:, None, None, :], s2[None, :, None, :])
    mean = triples.reshape(-1, 2).mean(axis=0)
    sd = triples.reshape(-1, 2).std(axis=0)
    for out in (ex, sa):
        assert np.all(np.abs(out.landmarks_fl["L3"].mean(axis=0) - mean) < 5 * sd / np.sqrt(20_000))


@given(st.lists(st.floats(0.0, 10.0), min_size=1, max_size=40), st.integers(1, 500), seed_s)
def test_resampling_keeps_the_count(w: list[float], n: int, seed: int) -> None:
    weights = np.array(w)
    if weights.sum() <= 0:
        weights[0] = 1.0
    idx = systematic_resample(weights, n, np.random.default_rng(seed))
    assert idx.shape == (n,)
    assert np.all(weights[idx] > 0)


def test_resampling_is_unbiased() -> None:
    rng = np.random.default_rng(7)
    w = rng.random(13) ** 3
    n, trials = 40, 20_000
    counts = np.zeros(13)
    for _ in range(trials):
        counts += np.bincount(systematic_resample(w, n, rng), minlength=13)
    expected = n * w / w.sum()
    # systematic counts are floor/ceil of the expectation: per-trial sd <= 0.5
    np.testing.assert_allclose(counts / trials, expected, atol=5 * 0.5 / np.sqrt(trials))
