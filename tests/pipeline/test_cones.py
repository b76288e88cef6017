"""Cone intersection A_i, uniform sampling in it, degenerate geometry (docs/method.md, part 3)."""

from __future__ import annotations

import math

import numpy as np
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
    assert np.all(region.contains(s))
    assert bool(region.contains(p[None, :])[0])  # the truth is inside A_i


@given(landmark_s, st.integers(0, 2**32 - 1))
def test_uniform_draws_fill_the_region(p: np.ndarray, seed: int) -> None:
    b1, b2 = _bearings(p)
    region = intersect_cones(b1, b2, EPS, 0.1, 20.0)
    assume(isinstance(region, ConeIntersection))
    assert isinstance(region, ConeIntersection)
    pts = region.sample_uniform(2000, np.random.default_rng(seed))
    assert pts.shape == (2000, 2)
    assert np.all(region.contains(pts))


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
