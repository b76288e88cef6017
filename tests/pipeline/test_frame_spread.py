"""The second moment of a landmark whose error is a turn and a scaling about the reference pair
(pipeline/joint/frame_spread.py), against sampling: points drawn in (log distance, direction)
about the pair's midpoint, mapped to x, y, their mean square offset from the estimate."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.joint.frame_spread import frame_spread_cov

PIVOT = np.array([0.5, 0.0])
CHI2_2_80 = -2.0 * math.log(0.2)


def _polar_cov(mean_fl: np.ndarray, s_polar: np.ndarray) -> np.ndarray:
    """The x, y covariance that a (log distance, direction) covariance stands for to first
    order at ``mean_fl``: J s J' with J the derivative of pivot + exp(u) (cos phi, sin phi)."""
    z = mean_fl - PIVOT
    rho, phi = math.hypot(*z), math.atan2(z[1], z[0])
    jac = rho * np.array([[math.cos(phi), -math.sin(phi)], [math.sin(phi), math.cos(phi)]])
    return jac @ s_polar @ jac.T


def _sampled(mean_fl: np.ndarray, s_polar: np.ndarray, n: int, seed: int) -> np.ndarray:
    """Points (n, 2) FL drawn with (log distance, direction) about the pivot ~ N(at the
    estimate, s_polar)."""
    z = mean_fl - PIVOT
    centre = [math.log(math.hypot(*z)), math.atan2(z[1], z[0])]
    up = np.random.default_rng(seed).multivariate_normal(centre, s_polar, n)
    return PIVOT + np.exp(up[:, :1]) * np.column_stack((np.cos(up[:, 1]), np.sin(up[:, 1])))


@pytest.mark.parametrize(
    ("mean", "s_polar"),
    [
        ((3.0, 2.0), [[0.01, 0.0], [0.0, 0.04]]),  # a wide turn: 11 deg
        ((-2.0, 0.5), [[0.04, 0.015], [0.015, 0.02]]),  # scale and turn, correlated
        ((0.5, -4.0), [[0.0025, -0.002], [-0.002, 0.09]]),  # 17 deg
    ],
)
def test_second_moment_matches_sampling(
    mean: tuple[float, float], s_polar: list[list[float]]
) -> None:
    m, s = np.array(mean), np.array(s_polar)
    out = frame_spread_cov(m, _polar_cov(m, s))
    pts = _sampled(m, s, 400_000, seed=5) - m
    sampled = pts.T @ pts / len(pts)
    # compared in the sampled moment's own axes (the thin axis as closely as the wide one):
    # sampling error of a second moment at 400,000 draws is about 0.5% of each
    white = np.linalg.inv(np.linalg.cholesky(sampled))
    assert np.allclose(white @ out @ white.T, np.eye(2), atol=0.02), (out, sampled)
    # and it is not the first-order covariance it started from
    first = np.linalg.eigvalsh(white @ _polar_cov(m, s) @ white.T)
    assert first.min() < 0.95, first


def test_small_errors_keep_the_first_order_covariance() -> None:
    m = np.array([2.0, 1.0])
    cov = np.array([[4e-6, 1e-6], [1e-6, 2e-6]])
    assert np.allclose(frame_spread_cov(m, cov), cov, rtol=1e-4, atol=0.0)


def test_a_wide_turn_widens_the_region_across_the_line_of_sight_and_holds_80_percent() -> None:
    # 4 FL from the pair, a 14 deg turn: the truths lie on an arc that sags 0.12 FL off its
    # tangent; the first-order ellipse is 0.06 FL thick there
    m = np.array([4.5, 0.0])
    s = np.array([[0.015**2, 0.0], [0.0, 0.25**2]])
    lin = _polar_cov(m, s)
    out = frame_spread_cov(m, lin)
    assert out[0, 0] > 2.0 * lin[0, 0]  # radial: along x here
    truth = _sampled(m, s, 200_000, seed=11) - m

    def inside(cov: np.ndarray) -> float:
        d2 = np.einsum("ni,ij,nj->n", truth, np.linalg.inv(cov), truth)
        return float(np.mean(d2 <= CHI2_2_80))

    assert inside(lin) < 0.75
    assert 0.78 <= inside(out) <= 0.9


@pytest.mark.parametrize(
    ("mean", "cov"),
    [
        ((0.6, 0.1), [[0.01, 0.0], [0.0, 0.01]]),  # the pole within 3 std
        ((3.0, 0.0), [[0.01, 0.0], [0.0, -0.01]]),  # not positive definite
        ((3.0, 0.0), [[np.inf, 0.0], [0.0, 0.01]]),
    ],
)
def test_left_as_it_is_where_the_polar_form_means_nothing(
    mean: tuple[float, float], cov: list[list[float]]
) -> None:
    c = np.array(cov)
    assert np.array_equal(frame_spread_cov(np.array(mean), c), c)
