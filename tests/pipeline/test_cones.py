"""Cone intersection A_i, uniform sampling in it, degenerate geometry (docs/method.md, part 3)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from pipeline.cones import ConeIntersection, Degenerate, intersect_cones
from pipeline.init_fr import initialize_fr
from pipeline.priors import GaussianPrior, ImpartialPrior, MixturePrior

EPS = math.radians(3.0)


def _bearings(p: np.ndarray) -> tuple[float, float]:
    return math.atan2(p[1], p[0]), math.atan2(p[1], p[0] - 1.0)


def _in_cone(pts: np.ndarray, origin: np.ndarray, bearing: float, eps: float) -> np.ndarray:
    d = pts - origin
    da = np.angle(np.exp(1j * (np.arctan2(d[:, 1], d[:, 0]) - bearing)))
    return np.abs(da) <= eps + 1e-9


def _in_a_i(
    pts: np.ndarray, b1: float, b2: float, eps: float, r_min: float, r_max: float
) -> np.ndarray:
    """The oracle of A_i: angles and distances measured directly from O1 = (0, 0), O2 = (1, 0)."""
    ok = np.ones(pts.shape[0], dtype=bool)
    for origin, bearing in ((np.zeros(2), b1), (np.array([1.0, 0.0]), b2)):
        d = np.hypot(pts[:, 0] - origin[0], pts[:, 1] - origin[1])
        ok &= _in_cone(pts, origin, bearing, eps) & (d >= r_min) & (d <= r_max)
    return ok


landmark_s = st.tuples(st.floats(-3.0, 4.0), st.floats(0.3, 4.0)).map(np.array)
sign_s = st.sampled_from([1.0, -1.0])


@given(
    landmark_s,
    sign_s,
    st.integers(0, 2**32 - 1),
    st.sampled_from(["impartial", "gaussian", "mixture"]),
)
def test_particles_lie_in_both_cones(p: np.ndarray, sign: float, seed: int, kind: str) -> None:
    p = p * np.array([1.0, sign])
    b1, b2 = _bearings(p)
    region = intersect_cones(b1, b2, EPS, 0.1, 20.0)
    assume(isinstance(region, ConeIntersection))
    assert isinstance(region, ConeIntersection)
    prior = {"impartial": ImpartialPrior, "gaussian": GaussianPrior, "mixture": MixturePrior}[kind]
    s = initialize_fr(region, prior(EPS), 50, np.random.default_rng(seed))
    assert not isinstance(s, Degenerate)
    assert s.shape == (50, 2) and np.all(np.isfinite(s))
    assert np.all(_in_cone(s, np.zeros(2), b1, EPS))
    assert np.all(_in_cone(s, np.array([1.0, 0.0]), b2, EPS))
    assert np.all(_in_a_i(s, b1, b2, EPS, 0.1 * (1 - 1e-12), 20.0 * (1 + 1e-12)))
    assert bool(region.contains(p[None, :])[0])  # the truth is inside A_i


@given(landmark_s, st.integers(0, 2**32 - 1))
def test_uniform_draws_lie_in_the_measured_region(p: np.ndarray, seed: int) -> None:
    b1, b2 = _bearings(p)
    region = intersect_cones(b1, b2, EPS, 0.1, 20.0)
    assume(isinstance(region, ConeIntersection))
    assert isinstance(region, ConeIntersection)
    pts = region.sample_uniform(2000, np.random.default_rng(seed))
    assert pts.shape == (2000, 2)
    assert np.all(_in_a_i(pts, b1, b2, EPS, 0.1 * (1 - 1e-12), 20.0 * (1 + 1e-12)))


# (landmark, eps, r_min, r_max): both annuli cut the wedges; a landmark 15 cm from O2, and one
# 15 cm from O1, where r_min = 0.1 bites; a far landmark whose region r_max cuts at O1
GEOMETRIES = [
    ((0.5, 0.5), math.radians(10.0), 0.66, 0.76),
    ((1.1, 0.11), EPS, 0.1, 20.0),
    ((-0.1, 0.11), EPS, 0.1, 20.0),
    ((3.0, -2.0), EPS, 0.1, 3.5),
]


@pytest.mark.parametrize(
    ("landmark", "eps", "r_min", "r_max"),
    GEOMETRIES,
    ids=["both-annuli", "near-O2", "near-O1", "r_max-at-O1"],
)
def test_region_and_its_draws_against_measured_angles_and_distances(
    landmark: tuple[float, float], eps: float, r_min: float, r_max: float
) -> None:
    b1, b2 = _bearings(np.array(landmark))
    region = intersect_cones(b1, b2, eps, r_min, r_max)
    assert isinstance(region, ConeIntersection)
    rng = np.random.default_rng(11)
    lo = region.polygon.min(axis=0) - 0.05
    hi = region.polygon.max(axis=0) + 0.05
    box = rng.uniform(lo, hi, (200_000, 2))
    inside = _in_a_i(box, b1, b2, eps, r_min, r_max)
    wedges = _in_a_i(box, b1, b2, eps, 0.0, np.inf)
    assert inside.sum() > 1000 and (wedges & ~inside).sum() > 1000  # the ranges cut the region
    np.testing.assert_array_equal(region.contains(box), inside)
    draws = region.sample_uniform(20_000, rng)
    assert draws.shape == (20_000, 2)
    assert np.all(_in_a_i(draws, b1, b2, eps, r_min * (1 - 1e-12), r_max * (1 + 1e-12)))
    # uniform: the draws fall in a 4 x 4 grid of cells as the measured area of A_i does
    edges = [np.linspace(lo[k], hi[k], 5) for k in (0, 1)]
    area, _, _ = np.histogram2d(box[inside, 0], box[inside, 1], bins=edges)
    got, _, _ = np.histogram2d(draws[:, 0], draws[:, 1], bins=edges)
    want = 20_000 * area / inside.sum()
    # binomial spread of the draws plus that of the area estimate: 5 sigma
    sigma = np.sqrt(want + (20_000 / inside.sum()) ** 2 * area) + 1.0
    assert np.all(np.abs(got - want) < 5.0 * sigma), (got, want)


def test_parallel_bearings_are_degenerate() -> None:
    for b in (0.0, 0.02, math.pi - 0.01, -math.pi + 0.03, 1.0):
        out = intersect_cones(b, b + 0.5 * EPS, EPS, 0.1, 20.0)
        assert isinstance(out, Degenerate)
        assert "parallel" in out.reason


def test_diverging_bearings_do_not_meet() -> None:
    out = intersect_cones(math.radians(80), math.radians(60), EPS, 0.1, 20.0)
    assert isinstance(out, Degenerate) and "do not meet" in out.reason


def test_region_beyond_r_max_is_degenerate() -> None:
    p = np.array([0.5, 30.0])  # 30 movements away, parallax ~1.9 deg
    b1, b2 = _bearings(p)
    out = intersect_cones(b1, b2, math.radians(0.3), 0.1, 20.0)
    assert isinstance(out, Degenerate) and "r_max" in out.reason


def test_region_nearer_than_r_min_is_degenerate() -> None:
    p = np.array([0.5, 0.05])
    b1, b2 = _bearings(p)
    out = intersect_cones(b1, b2, EPS, 0.9, 20.0)
    assert isinstance(out, Degenerate) and "r_min" in out.reason


def test_non_finite_bearing_is_degenerate() -> None:
    out = intersect_cones(float("nan"), 1.0, EPS, 0.1, 20.0)
    assert isinstance(out, Degenerate) and "finite" in out.reason
