"""Movements of a session: turn in place, then drive straight; and random plans for a robot."""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from data_schemas.angles import wrap_rad


@dataclass(frozen=True)
class Move:
    """One movement: turn in place by ``turn_rad`` (CCW), then drive ``distance_m`` straight."""

    turn_rad: float
    distance_m: float


def random_moves(
    rng: np.random.Generator,
    count: int | None,
    distance_m: tuple[float, float],
    turn_rad: float | None = None,
) -> Iterator[Move]:
    """Moves for a real robot: turn uniform in [-pi, pi) (or ``turn_rad``), distance uniform.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the pseudo-random turns and distances.
    count : int or None
        Number of moves; None for endless (stop with Ctrl-C).
    distance_m : (float, float)
        Range of the straight distance, metres (equal bounds for a fixed distance).
    turn_rad : float, optional
        Fixed turn instead of a random one.
    """
    lo, hi = distance_m
    if not 0 < lo <= hi:
        raise ValueError(f"distance range must satisfy 0 < lo <= hi, got {distance_m}")
    i = 0
    while count is None or i < count:
        angle = (
            turn_rad if turn_rad is not None else wrap_rad(float(rng.uniform(-math.pi, math.pi)))
        )
        yield Move(angle, float(rng.uniform(lo, hi)) if hi > lo else lo)
        i += 1
