"""Properties of the impartial PDF and of the two baseline priors (docs/method.md, part 2)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.integrate import trapezoid  # numpy.trapezoid is numpy 2 only

from pipeline.priors import (
    GaussianPrior,
    ImpartialPrior,
    MixturePrior,
    prior_density_grid,
    range_marginal,
)

eps_s = st.floats(math.radians(0.5), math.radians(20.0))
bearing_s = st.floats(-math.pi, math.pi, exclude_max=True)
rmin_s = st.floats(0.01, 1.0)
span_s = st.floats(0.5, 50.0)
angular_s = st.sampled_from(["gaussian", "uniform"])


#: 200 Gauss-Legendre nodes and weights on [-1, 1], computed once for every example
NODES_200 = np.polynomial.legendre.leggauss(200)


def _polar_integral(prior: ImpartialPrior, bearing: float) -> float:
    """∫∫ p(x, y) dx dy over the cone, by Gauss-Legendre in (r, a) with the r dr da element."""
    xr, wr = NODES_200
    xa, wa = NODES_200
    r = 0.5 * (prior.r_max - prior.r_min) * xr + 0.5 * (prior.r_max + prior.r_min)
    wr = wr * 0.5 * (prior.r_max - prior.r_min)
    a = bearing + prior.eps_rad * xa
    wa = wa * prior.eps_rad
    rr, aa = np.meshgrid(r, a, indexing="ij")
    pts = np.column_stack(((rr * np.cos(aa)).ravel(), (rr * np.sin(aa)).ravel()))
    dens = prior.density(pts, np.zeros(2), bearing).reshape(rr.shape)
    return float(wr @ (dens * rr) @ wa)


@given(eps_s, bearing_s, rmin_s, span_s, angular_s)
def test_impartial_integrates_to_one(
    eps: float, bearing: float, r_min: float, span: float, angular: str
) -> None:
    prior = ImpartialPrior(eps, r_min, r_min + span, angular=angular)  # type: ignore[arg-type]
    assert math.isclose(_polar_integral(prior, bearing), 1.0, rel_tol=1e-6)


@given(eps_s, bearing_s, rmin_s, span_s, angular_s)
def test_impartial_range_marginal_is_uniform(
    eps: float, bearing: float, r_min: float, span: float, angular: str
) -> None:
    prior = ImpartialPrior(eps, r_min, r_min + span, angular=angular)  # type: ignore[arg-type]
    r = np.linspace(r_min, r_min + span, 9)[1:-1]
    marg = range_marginal(prior, r, bearing, n_angle=64)
    np.testing.assert_allclose(marg, 1.0 / span, rtol=1e-6)


def test_baseline_range_marginals_are_not_uniform() -> None:
    eps, r_min, r_max = math.radians(3.0), 0.1, 20.0
    r = np.linspace(0.5, 19.5, 39)
    for prior in (GaussianPrior(eps, r_min, r_max), MixturePrior(eps, r_min, r_max)):
        marg = range_marginal(prior, r)
        # the same measure that is exactly flat for the impartial PDF varies by far more than 2x
        assert marg.max() > 2.0 * marg.min(), type(prior).__name__
    flat = range_marginal(ImpartialPrior(eps, r_min, r_max), r)
    assert flat.max() < 1.000001 * flat.min()


@given(eps_s, bearing_s, rmin_s, span_s, angular_s, st.integers(0, 2**32 - 1))
def test_impartial_samples_lie_in_the_cone(
    eps: float, bearing: float, r_min: float, span: float, angular: str, seed: int
) -> None:
    prior = ImpartialPrior(eps, r_min, r_min + span, angular=angular)  # type: ignore[arg-type]
    origin = np.array([0.3, -0.7])
    pts = prior.sample(500, origin, bearing, np.random.default_rng(seed))
    d = pts - origin
    r = np.sqrt((d * d).sum(axis=1))
    da = np.angle(np.exp(1j * (np.arctan2(d[:, 1], d[:, 0]) - bearing)))
    assert np.all(np.abs(da) <= eps * (1 + 1e-9))
    assert np.all((r >= r_min * (1 - 1e-9)) & (r <= (r_min + span) * (1 + 1e-9)))
    assert np.all(prior.density(pts, origin, bearing) > 0.0)


def test_impartial_sample_ranges_are_uniform() -> None:
    prior = ImpartialPrior(math.radians(3.0), 0.5, 10.5)
    pts = prior.sample(40_000, np.zeros(2), 1.0, np.random.default_rng(1))
    counts, _ = np.histogram(np.sqrt((pts**2).sum(axis=1)), bins=10, range=(0.5, 10.5))
    # 4000 expected per bin, std ~60: 5 sigma
    assert np.all(np.abs(counts - 4000) < 300)


def test_density_zero_outside_the_cone() -> None:
    prior = ImpartialPrior(math.radians(3.0), 0.1, 20.0)
    outside = np.array([[-1.0, 0.0], [1.0, 0.2], [0.05, 0.0], [25.0, 0.0]])
    assert np.all(prior.density(outside, np.zeros(2), 0.0) == 0.0)


def test_density_grid_is_the_density_on_the_grid() -> None:
    xs = np.linspace(-1.0, 21.0, 221)
    ys = np.linspace(-3.0, 3.0, 121)
    # three grid points with the density written out: the impartial PDF at (10, 0) seen along
    # +x is g(0) / ((r_max - r_min) 10); the Gaussian prior's peak is on its mean range 10.05
    eps, r_min, r_max = math.radians(3.0), 0.1, 20.0
    g0 = 1.0 / (0.5 * eps * math.sqrt(2.0 * math.pi) * math.erf(2.0 / math.sqrt(2.0)))
    impartial = prior_density_grid("impartial", 0.0, eps, r_min, r_max, xs, ys)
    assert impartial.shape == (121, 221)
    assert impartial[60, 110] == pytest.approx(g0 / ((r_max - r_min) * 10.0), rel=1e-12)
    assert impartial[0, 110] == 0.0 and impartial[60, 0] == 0.0  # outside the cone
    gaussian = prior_density_grid("gaussian", 0.0, eps, r_min, r_max, xs, ys)
    s_along, s_across = (r_max - r_min) / 4.0, 10.05 * 0.5 * eps
    peak = 1.0 / (2.0 * math.pi * s_along * s_across)
    assert gaussian[60, 110] == pytest.approx(peak * math.exp(-0.5 * (0.05 / s_along) ** 2))


def _ray_moments(pts: np.ndarray, origin: np.ndarray, bearing: float) -> tuple[float, ...]:
    """Mean and std of the draws along and across the ray."""
    d = pts - origin
    along = d[:, 0] * math.cos(bearing) + d[:, 1] * math.sin(bearing)
    across = d[:, 1] * math.cos(bearing) - d[:, 0] * math.sin(bearing)
    return float(along.mean()), float(along.std()), float(across.mean()), float(across.std())


def test_baseline_priors_against_their_formulas() -> None:
    """Density, mass and draws of the two baselines against values written out by hand."""
    eps, r_min, r_max, bearing = math.radians(3.0), 0.1, 20.0, 0.7
    origin = np.array([0.3, -0.7])
    ray = np.array([math.cos(bearing), math.sin(bearing)])
    normal = np.array([-ray[1], ray[0]])
    rng = np.random.default_rng(31)
    # one Gaussian: mean range 10.05, range std 19.9 / 4, cross std 10.05 * eps / 2
    r0, sa, sc = 10.05, 4.975, 10.05 * 0.5 * eps
    gaussian = GaussianPrior(eps, r_min, r_max)
    pts = origin + np.array([r0 * ray, (r0 + sa) * ray, r0 * ray + sc * normal])
    peak = 1.0 / (2.0 * math.pi * sa * sc)
    want = [peak, peak * math.exp(-0.5), peak * math.exp(-0.5)]
    np.testing.assert_allclose(gaussian.density(pts, origin, bearing), want, rtol=1e-12)
    m_along, s_along, m_across, s_across = _ray_moments(
        gaussian.sample(200_000, origin, bearing, rng), origin, bearing
    )
    # 200k draws: standard errors 0.011 along, 0.0006 across
    assert abs(m_along - r0) < 0.05 and abs(s_along - sa) < 0.05
    assert abs(m_across) < 0.003 and abs(s_across - sc) < 0.003
    # the Sola series for r_min = 0.1, alpha = 0.3: s0 = 0.1 / 0.7, beta = 1.3 / 0.7; the first
    # s_j with s_j * 1.3 >= 20 is j = 8 (beta^8 = 141 >= 20 / (1.3 s0) = 108), so 9 terms
    s = 0.1 / 0.7 * (1.3 / 0.7) ** np.arange(9)
    mixture = MixturePrior(eps, r_min, r_max)
    np.testing.assert_allclose(mixture.means(), s, rtol=1e-12)
    at = origin + np.outer(s[:2], ray)
    terms = np.exp(-0.5 * ((s[:2, None] - s[None, :]) / (0.3 * s[None, :])) ** 2) / (
        2.0 * math.pi * (0.3 * s) * (0.5 * eps * s)
    )
    np.testing.assert_allclose(mixture.density(at, origin, bearing), terms.mean(axis=1))
    m_along, s_along, _, _ = _ray_moments(
        mixture.sample(200_000, origin, bearing, rng), origin, bearing
    )
    mean = s.mean()  # equal weights; each term adds its variance (0.3 s_j)^2
    std = math.sqrt(float(np.mean((0.3 * s) ** 2 + s**2)) - mean**2)
    assert abs(m_along - mean) < 0.03 and abs(s_along - std) < 0.03
    # the Gaussian integrates to one over the plane (Gauss-Legendre on [-15, 35] x [-3, 3])
    x, wx = np.polynomial.legendre.leggauss(200)
    gx, gy = np.meshgrid(25.0 * x + 10.0, 3.0 * x, indexing="ij")
    dens = gaussian.density(np.column_stack((gx.ravel(), gy.ravel())), np.zeros(2), 0.0)
    assert float((25.0 * wx) @ dens.reshape(gx.shape) @ (3.0 * wx)) == pytest.approx(1.0, abs=1e-3)


def test_angular_density_and_its_draws_against_the_truncated_normal() -> None:
    eps = math.radians(3.0)
    s = 0.5 * eps  # the default std: half the error bound, cut at 2 std
    prior = ImpartialPrior(eps)
    peak = 1.0 / (s * math.sqrt(2.0 * math.pi) * math.erf(2.0 / math.sqrt(2.0)))
    da = np.array([0.0, s, -s, eps, -eps, 1.0001 * eps])
    want = peak * np.array([1.0, math.exp(-0.5), math.exp(-0.5), math.exp(-2.0), math.exp(-2.0), 0])
    np.testing.assert_allclose(prior.g(da), want, rtol=1e-12)
    # draws: the truncated normal's std, by the trapezoid rule on its density written out
    x = np.linspace(-eps, eps, 20_001)
    dens = np.exp(-0.5 * (x / s) ** 2)
    std = math.sqrt(float(trapezoid(x * x * dens, x) / trapezoid(dens, x)))
    draws = prior.sample_angle(200_000, np.random.default_rng(41))
    assert np.abs(draws).max() <= eps
    # 200k draws: the std's standard error is ~0.2 %
    assert float(draws.std()) == pytest.approx(std, rel=0.01)
    assert abs(float(draws.mean())) < 5 * std / math.sqrt(200_000)
    flat = ImpartialPrior(eps, angular="uniform")
    np.testing.assert_allclose(flat.g(da), [1 / (2 * eps)] * 5 + [0.0], rtol=1e-12)
    assert float(flat.sample_angle(200_000, np.random.default_rng(42)).std()) == pytest.approx(
        eps / math.sqrt(3.0), rel=0.01
    )


@pytest.mark.parametrize("n", [1, 2, 7, 64, 2048])
def test_gauss_legendre_matches_scipy(n: int) -> None:
    """Our Newton nodes and weights against scipy's Golub-Welsch (an independent method)."""
    from scipy.special import roots_legendre

    from pipeline.priors import _gauss_legendre

    x, w = _gauss_legendre(n)
    x_ref, w_ref = roots_legendre(n)
    np.testing.assert_allclose(x, x_ref, rtol=0, atol=1e-14)
    np.testing.assert_allclose(w, w_ref, rtol=0, atol=1e-12)
