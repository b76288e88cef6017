"""The search among unnamed detections: crossings of a movement's rays, and the count of
keyframes whose rays pass near a point (``pipeline/association/hypotheses.py``)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.association.hypotheses import Ray, RaySet, crossings

EPS = math.radians(3.0)
ANGLE = st.floats(-math.pi, math.pi, allow_nan=False)


def _ray(movement: int, end: int, origin: tuple[float, float], direction: float) -> Ray:
    return Ray(movement, end, 0, direction, origin, direction)


def _crossing_ahead(a: Ray, b: Ray) -> tuple[float, float] | None:
    """Scalar reference: where ``a`` and ``b`` cross ahead of both with 2 eps of parallax."""
    ca, sa = math.cos(a.direction_rad), math.sin(a.direction_rad)
    cb, sb = math.cos(b.direction_rad), math.sin(b.direction_rad)
    cross = ca * sb - sa * cb
    if cross == 0.0:
        return None
    dx, dy = b.origin_fl[0] - a.origin_fl[0], b.origin_fl[1] - a.origin_fl[1]
    ta, tb = (dx * sb - dy * cb) / cross, (dx * sa - dy * ca) / cross
    parallax = abs(math.remainder(a.direction_rad - b.direction_rad, math.tau))
    if ta <= 0.0 or tb <= 0.0 or parallax < 2 * EPS:
        return None
    return a.origin_fl[0] + ta * ca, a.origin_fl[1] + ta * sa


@settings(max_examples=300)
@given(st.lists(ANGLE, min_size=1, max_size=4), st.lists(ANGLE, min_size=1, max_size=4))
def test_crossings_are_the_pairs_that_meet_ahead_with_parallax(
    at_o1: list[float], at_o2: list[float]
) -> None:
    # movement 3 from (0, 0) to (0.3, 0.1); an older keyframe's rays must not take part
    o1, o2 = (0.0, 0.0), (0.3, 0.1)
    rays = [_ray(3, 0, o1, d) for d in at_o1] + [_ray(3, 1, o2, d) for d in at_o2]
    rays.append(_ray(1, 0, (1.0, 1.0), 0.5))
    expected = [
        p for a in rays[: len(at_o1)] for b in rays[len(at_o1) : -1] if (p := _crossing_ahead(a, b))
    ]
    got = crossings(RaySet(rays), 3, 2 * EPS)
    assert got.shape == (len(expected), 2)
    for p in expected:
        assert np.min(np.hypot(*(got - p).T)) <= 1e-6 * max(1.0, math.hypot(*p))


def test_keyframes_are_counted_once_whatever_their_rays() -> None:
    # three keyframes look at (1, 1): one of them with two rays near it, one with a ray that
    # points away, one behind the point (its ray points the other way)
    point = np.array([[1.0, 1.0]])
    toward = lambda o: math.atan2(1.0 - o[1], 1.0 - o[0])  # noqa: E731
    rays = [
        _ray(0, 0, (0.0, 0.0), toward((0.0, 0.0))),
        _ray(0, 0, (0.0, 0.0), toward((0.0, 0.0)) + 0.5 * EPS),
        _ray(0, 1, (0.5, 0.0), toward((0.5, 0.0)) + 0.2),
        _ray(1, 1, (2.0, 0.0), toward((2.0, 0.0))),
        _ray(2, 0, (0.0, 2.0), toward((0.0, 2.0)) + math.pi),
    ]
    rs = RaySet(rays)
    err = rs.errors(point)
    assert rs.keyframes_within(err, EPS).tolist() == [2]
    nearest = rs.nearest_per_keyframe(err[0], EPS)
    assert [(r.movement, r.end) for r in nearest] == [(0, 0), (1, 1)]
    assert nearest[0] is rays[0]  # the nearer of the two rays of keyframe (0, 0)
