"""Clocks: one monotonic clock for ordering plus wall time; a virtual clock for simulation.

The recorder never calls :mod:`time` directly: it takes a :class:`Clock`. On a robot that is
:class:`SystemClock`; in simulation :class:`VirtualClock`, whose ``sleep`` advances time at once,
so a session simulates much faster than real time with the same code path.
"""

from __future__ import annotations

import threading
import time
from typing import Protocol


class Clock(Protocol):
    """Time source for the recorder (integer nanoseconds)."""

    def monotonic_ns(self) -> int:
        """Monotonic time, for ordering and durations."""
        ...

    def wall_ns(self) -> int:
        """Wall-clock time since the Unix epoch."""
        ...

    def sleep(self, seconds: float) -> None:
        """Wait ``seconds`` (virtual clocks just advance)."""
        ...


class SystemClock:
    """The real clocks of this machine."""

    def monotonic_ns(self) -> int:
        return time.monotonic_ns()

    def wall_ns(self) -> int:
        return time.time_ns()

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)


class VirtualClock:
    """Simulated time: starts at ``start_wall_ns`` and moves only when someone sleeps/advances.

    Thread-safe, so a fake device serving a pty in another thread can read it.
    """

    def __init__(self, start_wall_ns: int = 1_700_000_000 * 1_000_000_000) -> None:
        self._lock = threading.Lock()
        self._elapsed_ns = 0
        self._start_wall_ns = start_wall_ns

    def monotonic_ns(self) -> int:
        with self._lock:
            return self._elapsed_ns

    def wall_ns(self) -> int:
        with self._lock:
            return self._start_wall_ns + self._elapsed_ns

    def sleep(self, seconds: float) -> None:
        self.advance_ns(round(seconds * 1e9))

    def advance_ns(self, dt_ns: int) -> None:
        """Move time forward by ``dt_ns`` (negative values are ignored)."""
        if dt_ns > 0:
            with self._lock:
                self._elapsed_ns += dt_ns


class PacedClock(VirtualClock):
    """Simulated time that runs at most ``speed`` times as fast as real time.

    Time still moves only when someone sleeps, exactly as with :class:`VirtualClock` (so a
    simulated log holds the same messages at any speed); each sleep then also waits, in real
    time, until ``speed`` x the real seconds since the clock was made catch up with the simulated
    seconds. A follower thus sees the log grow as it would during a recording at that speed.

    Parameters
    ----------
    speed : float
        Simulated seconds per real second (> 0): 1 is real time, 4 four times as fast.
    """

    def __init__(self, speed: float, start_wall_ns: int = 1_700_000_000 * 1_000_000_000) -> None:
        if not speed > 0:
            raise ValueError(f"speed must be > 0, got {speed}")
        super().__init__(start_wall_ns)
        self.speed = float(speed)
        self._t0 = time.monotonic()

    def advance_ns(self, dt_ns: int) -> None:
        super().advance_ns(dt_ns)
        due = self._t0 + self.monotonic_ns() / 1e9 / self.speed
        wait = due - time.monotonic()
        if wait > 0:
            time.sleep(wait)
