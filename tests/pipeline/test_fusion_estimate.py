"""Fusion of two FL beliefs, estimates and credible regions, batch LS and the CRB."""

from __future__ import annotations

import math

import numpy as np

from pipeline.batch_ls import batch_least_squares
from pipeline.crb import cramer_rao_bound, fisher_information, truncated_gaussian_std
from pipeline.estimate import LandmarkEstimate
from pipeline.fusion import Kde, fuse
from pipeline.synthetic import PAPER_REFERENCE, simulate_bearings


def test_fusing_two_gaussians_gives_their_product() -> None:
    rng = np.random.default_rng(0)
    ca, cb = np.diag([0.04, 0.01]), np.array([[0.01, 0.005], [0.005, 0.03]])
    ma, mb = np.array([0.0, 0.0]), np.array([0.2, 0.1])
    pa = np.linalg.inv(ca)
    pb = np.linalg.inv(cb)
    cov = np.linalg.inv(pa + pb)
    mean = cov @ (pa @ ma + pb @ mb)
    means, covs = [], []
    for _ in range(40):
        a = rng.multivariate_normal(ma, ca, 300)
        b = rng.multivariate_normal(mb, cb, 300)
        out = fuse(a, b, 300, rng)
        assert out.shape == (300, 2)
        means.append(out.mean(axis=0))
        covs.append(np.cov(out.T))
    assert np.all(np.abs(np.mean(means, axis=0) - mean) < 0.01)
    # KDE smoothing adds at most h^2 = 15% to the product covariance
    np.testing.assert_allclose(np.mean(covs, axis=0), cov, rtol=0.3, atol=2e-3)


def test_shrinkage_kde_keeps_mean_and_covariance() -> None:
    rng = np.random.default_rng(1)
    x = rng.multivariate_normal([1.0, -2.0], [[0.3, 0.1], [0.1, 0.2]], 300)
    kde = Kde.fit(x)
    draws = kde.sample(200_000, rng)
    np.testing.assert_allclose(draws.mean(axis=0), x.mean(axis=0), atol=0.01)
    np.testing.assert_allclose(np.cov(draws.T), np.cov(x.T), atol=0.01)
    # the density integrates to 1 on a grid
    g = np.linspace(-3, 5, 161)
    gx, gy = np.meshgrid(g, g - 3)
    dens = np.exp(kde.logpdf(np.column_stack((gx.ravel(), gy.ravel()))))
    assert math.isclose(dens.sum() * (g[1] - g[0]) ** 2, 1.0, rel_tol=1e-3)


def test_kde_and_estimate_leave_the_particles_alone() -> None:
    # (2, n) work copies: a Fortran-ordered (n, 2) set is such a view already; it must be copied
    rng = np.random.default_rng(3)
    x = np.asfortranarray(rng.normal([1.0, -2.0], 0.1, (50, 2)))
    w = rng.random(50)
    before = x.copy()
    LandmarkEstimate.from_particles(x, weights=w)
    Kde.fit(x, weights=w).sample(10, rng)
    np.testing.assert_array_equal(x, before)


def test_credible_ellipse_has_its_probability() -> None:
    rng = np.random.default_rng(2)
    cov = np.array([[0.5, 0.2], [0.2, 0.3]])
    est = LandmarkEstimate(np.array([1.0, 2.0]), cov)
    pts = rng.multivariate_normal(est.mean_fl, cov, 20_000)
    inside = np.mean([est.contains(p, 0.8) for p in pts])
    assert abs(inside - 0.8) < 0.015
    ring = est.credible_ellipse(0.8, 32)
    assert ring.shape == (32, 2)
    d = ring - est.mean_fl  # Mahalanobis by numpy's inverse, not by est.mahalanobis2
    m2 = np.einsum("ni,ij,nj->n", d, np.linalg.inv(cov), d)
    np.testing.assert_allclose(m2, -2 * math.log(0.2), rtol=1e-9)


def test_batch_ls_is_exact_on_noiseless_bearings() -> None:
    run = simulate_bearings(6, np.random.default_rng(3), eps_rad=1e-9)
    names = list(run.landmarks_world)
    est = batch_least_squares(run.observations, names, PAPER_REFERENCE)
    truth = run.truth_fl()
    for n in ("L3", "L4"):
        np.testing.assert_allclose(est[n], truth[n], atol=1e-6)


def test_crb_two_views_matches_closed_form() -> None:
    landmark = np.array([0.3, 2.0])
    obs = np.array([[0.0, 0.0], [1.0, 0.0]])
    sigma = 0.01
    j = fisher_information(landmark, obs, sigma)
    d = landmark - obs
    r1, r2 = np.sqrt((d * d).sum(axis=1))
    gamma = math.atan2(d[0, 1], d[0, 0]) - math.atan2(d[1, 1], d[1, 0])
    assert math.isclose(np.linalg.det(j), math.sin(gamma) ** 2 / (sigma**4 * r1**2 * r2**2))
    np.testing.assert_allclose(cramer_rao_bound(landmark, obs, sigma) @ j, np.eye(2), atol=1e-9)
    assert np.all(np.isinf(cramer_rao_bound(landmark, obs[:1], sigma)))


def test_truncated_gaussian_std_matches_samples() -> None:
    rng = np.random.default_rng(4)
    x = rng.normal(0, 1.5, 2_000_000)
    x = x[np.abs(x) <= 3.0]
    assert math.isclose(truncated_gaussian_std(3.0, 0.5), float(x.std()), rel_tol=5e-3)
