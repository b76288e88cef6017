"""PacedClock: simulated time at most ``speed`` x real time, moving like VirtualClock."""

from __future__ import annotations

import time

import pytest

from recorder.clock import PacedClock, VirtualClock


def test_paced_clock_moves_like_the_virtual_clock_but_not_faster_than_its_speed() -> None:
    paced, virtual = PacedClock(speed=10.0), VirtualClock()
    t0 = time.monotonic()
    for _ in range(6):
        paced.sleep(0.05)
        virtual.sleep(0.05)
        assert paced.monotonic_ns() == virtual.monotonic_ns()
        # never ahead of speed x the real time since the clock was made
        assert paced.monotonic_ns() / 1e9 <= 10.0 * (time.monotonic() - t0) + 1e-3
    assert paced.wall_ns() == virtual.wall_ns()
    assert time.monotonic() - t0 >= 0.3 / 10.0


def test_paced_clock_lags_rather_than_jumps_when_the_caller_is_slow() -> None:
    paced = PacedClock(speed=100.0)
    time.sleep(0.05)  # the caller took 5 simulated seconds' worth of real time
    paced.sleep(0.1)  # due long ago: simulated time still moves by exactly what was slept
    assert paced.monotonic_ns() == 100_000_000


def test_speed_must_be_positive() -> None:
    with pytest.raises(ValueError, match="speed must be > 0"):
        PacedClock(speed=0.0)
