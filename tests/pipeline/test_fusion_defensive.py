"""The defensive mixture proposal of the likelihood fusion (a wide belief, a narrow likelihood)."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from pipeline.fusion import DEFENSIVE_DRAWS, Kde, LikelihoodUpdate, _mixture_draws, fuse_likelihood

N_L = 300
SD_L = 0.05  # the likelihood's width (FL units)


def _likelihood(centre: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """A narrow bounded likelihood (Gaussian of sd SD_L cut at 3 sd, like a bearing cone)."""

    def lik(x: np.ndarray) -> np.ndarray:
        d2 = ((x - centre) ** 2).sum(axis=1) / SD_L**2
        out: np.ndarray = np.where(d2 <= 9.0, np.exp(-0.5 * d2), 0.0)
        return out

    return lik


def _ess(w: np.ndarray) -> float:
    return float(w.sum()) ** 2 / float(w @ w) if w.sum() > 0 else 0.0


def _grid_mean(prev: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """Mean of q^ L on a grid over the likelihood's support (q^ = KDE of the belief)."""
    lik = _likelihood(centre)
    g = np.linspace(-3.2 * SD_L, 3.2 * SD_L, 241)
    gx, gy = np.meshgrid(centre[0] + g, centre[1] + g)
    pts = np.column_stack((gx.ravel(), gy.ravel()))
    dens = np.exp(Kde.fit(prev).logpdf(pts)) * lik(pts)
    out: np.ndarray = (pts * dens[:, None]).sum(axis=0) / dens.sum()
    return out


def _mean_and_error(res: LikelihoodUpdate) -> tuple[np.ndarray, np.ndarray]:
    """Self-normalised importance estimate of the mean and its Monte-Carlo standard error."""
    w = res.weights / res.weights.sum()
    mean = w @ res.points_fl
    se = np.sqrt((w[:, None] ** 2 * (res.points_fl - mean) ** 2).sum(axis=0))
    return mean, se


# the likelihood 4.2 sd out in the belief's tail (the belief's proposals miss it: None) and
# 2.5 sd out (a few hit it: low effective sample size; both draw sets are pooled)
# and with 4 times the particles, where the mixture makes DEFENSIVE_DRAWS draws, not 16 n_l
@pytest.mark.parametrize(
    ("offset", "seed", "n_l"),
    [
        (4.2, 0, N_L),
        (4.2, 1, N_L),
        (2.5, 2, N_L),
        (2.5, 3, N_L),
        (4.2, 4, 4 * N_L),
        (4.2, 5, 4 * N_L),
    ],
)
def test_defensive_proposal_recovers_the_product(offset: float, seed: int, n_l: int) -> None:
    rng = np.random.default_rng(seed)
    prev = rng.normal(0.0, 1.0, (n_l, 2))  # a wide first belief
    centre = np.array([offset, 0.3])
    lik = _likelihood(centre)
    # this movement's own set: where its bearings put the landmark, off the likelihood's peak
    # (it carries that movement's range prior), wider than the likelihood
    new_fl = rng.normal(centre + np.array([0.03, -0.02]), 2 * SD_L, (n_l, 2))

    plain = fuse_likelihood(prev, lik, n_l, rng)
    assert plain is None or _ess(plain.weights) < 10
    res = fuse_likelihood(prev, lik, n_l, rng, new_fl=new_fl)
    assert res is not None and res.defensive
    m_d = min(16 * n_l, DEFENSIVE_DRAWS)
    assert res.points_fl.shape[0] in (m_d, 16 * n_l + m_d)
    # as many effective draws as at the paper's n_l: the defensive draws stop at DEFENSIVE_DRAWS
    assert _ess(res.weights) > min(n_l, N_L)

    want = _grid_mean(prev, centre)
    got, se = _mean_and_error(res)
    # the belief's slope across the likelihood pulls the product towards the belief's mean by
    # several Monte-Carlo errors: a proposal density left out of the weights would show
    assert np.linalg.norm(want - centre) > 5 * se.max()
    np.testing.assert_array_less(np.abs(got - want), 4 * se)


def test_good_proposal_keeps_the_fast_path() -> None:
    """ESS >= n_l: the same draws and weights as without ``new_fl`` (same random stream)."""
    prev = np.random.default_rng(4).normal(0.0, 0.2, (N_L, 2))
    lik = _likelihood(np.array([0.0, 0.0]))

    def broad(x: np.ndarray) -> np.ndarray:
        out: np.ndarray = lik(x / 4.0)  # sd 0.2: about half the proposals count
        return out

    a = fuse_likelihood(prev, broad, N_L, np.random.default_rng(5))
    b = fuse_likelihood(prev, broad, N_L, np.random.default_rng(5), new_fl=prev + 3.0)
    assert a is not None and b is not None and not b.defensive
    assert _ess(a.weights) >= N_L
    np.testing.assert_array_equal(a.points_fl, b.points_fl)
    np.testing.assert_array_equal(a.weights, b.weights)


def test_no_support_anywhere_is_none() -> None:
    rng = np.random.default_rng(6)
    prev = rng.normal(0.0, 1.0, (N_L, 2))
    lik = _likelihood(np.array([40.0, 0.0]))  # beyond both the belief and this set
    assert fuse_likelihood(prev, lik, N_L, rng, new_fl=prev + 1.0) is None


def test_kde_log_density_near_and_far_from_every_kernel() -> None:
    """Blocked, anchored log density = the direct log-sum-exp, also hundreds of widths away."""
    rng = np.random.default_rng(7)
    x = rng.normal([3.0, -5.0], [0.01, 0.3], (300, 2))
    kde = Kde.fit(x, weights=rng.random(300))
    pts = np.vstack((kde.sample(700, rng), rng.normal(0.0, 30.0, (300, 2)), [[1e3, 1e3]]))
    wx = (pts[:, None, :] - kde.centres[None, :, :]) @ kde.whiten.T  # (m, n, 2) whitened
    terms = -0.5 * (wx**2).sum(axis=2) + np.log(kde.weights)
    top = terms.max(axis=1)
    want = top + np.log(np.exp(terms - top[:, None]).sum(axis=1)) + kde.log_norm
    assert want.min() < -1e6  # far points: every kernel term underflows without the anchor
    np.testing.assert_allclose(kde.logpdf(pts), want, rtol=1e-12, atol=1e-9)
    assert math.isclose(float(kde.logpdf(pts[:1])[0]), float(want[0]), rel_tol=1e-12)


@pytest.mark.slow
def test_mixture_density_is_the_density_of_its_draws() -> None:
    """E[q^(x) / mix(x)] = E[p^(x) / mix(x)] = 1 over draws x ~ mix (importance identity)."""
    rng = np.random.default_rng(8)
    q = Kde.fit(rng.normal(0.0, 1.0, (N_L, 2)))
    p = Kde.fit(rng.normal([1.0, 0.5], 0.4, (N_L, 2)))  # overlapping: the proportions matter
    x, lq, lp, log_mix = _mixture_draws(q, p, 200_000, rng)
    assert x.shape == (200_000, 2)
    np.testing.assert_allclose(lq, q.logpdf(x))
    for ratio in (np.exp(lq - log_mix), np.exp(lp - log_mix)):
        assert abs(ratio.mean() - 1.0) < 4 * ratio.std() / math.sqrt(ratio.size)
        assert ratio.std() / math.sqrt(ratio.size) < 0.005


def test_defensive_weights_equal_those_of_every_draw_bit_for_bit() -> None:
    # the two densities are evaluated only where L_t > 0; the weights must be the bits of the
    # evaluation at all 2 m draws (log L + log q^ - log mix), so results do not change
    rng = np.random.default_rng(11)
    prev = rng.normal(0.0, 1.0, (N_L, 2))
    new_fl = rng.normal([2.5, 0.0], 0.1, (N_L, 2))
    lik = _likelihood(np.array([2.5, 0.0]))
    for seed in range(4):
        got = fuse_likelihood(prev, lik, N_L, np.random.default_rng(seed), new_fl=new_fl)
        assert got is not None and got.defensive
        ref_rng = np.random.default_rng(seed)
        m = 16 * N_L
        Kde.fit(prev).sample(m, ref_rng)  # the plain draws come first
        xd, lq, _, log_mix = _mixture_draws(Kde.fit(prev), Kde.fit(new_fl), m, ref_rng)
        with np.errstate(divide="ignore"):
            log_w = np.log(lik(xd)) + lq - log_mix
        wd = np.exp(log_w - log_w.max())
        assert 0 < np.count_nonzero(wd) < m  # a subset: the case the shortcut is for
        plain = got.points_fl.shape[0] - m  # 0 when no plain draw had L_t > 0
        if plain:
            wd *= float(wd.sum()) / float(wd @ wd)
        assert np.array_equal(got.points_fl[plain:], xd)
        assert np.array_equal(got.weights[plain:], wd)
