"""The cheap pre-check of a pairing of rays: it may only refuse what the fit refuses."""

from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.association.hypotheses import Ray, cannot_meet, fit

EPS = math.radians(3.0)

COORD = st.floats(-2.0, 2.0, allow_nan=False)
ANGLE = st.floats(-math.pi, math.pi, allow_nan=False)


def _ray(end: int, x: float, y: float, direction: float) -> Ray:
    return Ray(0, end, 0, direction, (x, y), direction)


@settings(max_examples=1000)
@given(COORD, COORD, ANGLE, COORD, COORD, ANGLE, st.floats(0.0, 0.3))
def test_what_it_refuses_the_fit_refuses(
    x1: float, y1: float, d1: float, x2: float, y2: float, d2: float, near: float
) -> None:
    # half the cases: the second ray aimed near the crossing of the first, at its parallax limit
    r1 = _ray(0, x1, y1, d1)
    target = (x1 + math.cos(d1), y1 + math.sin(d1))
    if near:
        d2 = math.atan2(target[1] - y2, target[0] - x2) + (near - 0.15) * 0.2
    r2 = _ray(1, x2, y2, d2)
    if cannot_meet(r1, r2, EPS):
        assert fit("blue", [r1, r2], EPS, EPS / 2) is None


def test_it_refuses_the_plain_cases() -> None:
    o1, o2 = (0.0, 0.0), (1.0, 0.0)
    ahead = Ray(0, 0, 0, 0.0, o1, math.radians(60)), Ray(0, 1, 0, 0.0, o2, math.radians(120))
    assert not cannot_meet(*ahead, EPS) and fit("blue", list(ahead), EPS, EPS / 2) is not None
    # the lines cross at (0.5, 0.87): ahead of the first ray, behind the second
    behind = Ray(0, 0, 0, 0.0, o1, math.radians(60)), Ray(0, 1, 0, 0.0, o2, math.radians(-60))
    assert cannot_meet(*behind, EPS) and fit("blue", list(behind), EPS, EPS / 2) is None
    # meeting ahead 100 m away: a parallax of 0.6 deg, far below 2 eps
    far = (
        Ray(0, 0, 0, 0.0, o1, math.atan2(100, 0.5)),
        Ray(0, 1, 0, 0.0, o2, math.atan2(100, -0.5)),
    )
    assert cannot_meet(*far, EPS)
