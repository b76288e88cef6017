"""Properties of the impartial PDF and of the two baseline priors (docs/method.md, part 2)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

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


def test_density_grid_shape_and_mass() -> None:
    xs = np.linspace(-1.0, 21.0, 221)
    ys = np.linspace(-3.0, 3.0, 121)
    for name in ("impartial", "gaussian", "mixture"):
        grid = prior_density_grid(name, 0.0, math.radians(3.0), 0.1, 20.0, xs, ys)
        assert grid.shape == (121, 221)
        assert np.all(np.isfinite(grid)) and np.all(grid >= 0.0)
