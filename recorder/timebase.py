"""Session time: one monotonic clock, expressed in nanoseconds since the Unix epoch.

Every time stamp of a log (MCAP ``log_time`` and message ``timestamp`` fields) comes from
:class:`EpochClock`: the base clock's monotonic time, shifted so that the session's first
instant equals the wall time at that instant. Stamps therefore order like a monotonic clock
(never jump when NTP adjusts the wall clock) yet read as dates in Foxglove.
"""

from __future__ import annotations

from recorder.clock import Clock


class EpochClock:
    """A :class:`~recorder.clock.Clock` whose monotonic time is anchored at the wall epoch.

    Parameters
    ----------
    base : Clock
        Source of time (``SystemClock`` on a robot, ``VirtualClock`` in simulation).
    """

    def __init__(self, base: Clock) -> None:
        self.base = base
        self.start_monotonic_ns = base.monotonic_ns()
        self.start_wall_ns = base.wall_ns()

    def monotonic_ns(self) -> int:
        """Monotonic time, ns since the Unix epoch (equal to wall time at construction)."""
        return self.start_wall_ns + self.base.monotonic_ns() - self.start_monotonic_ns

    def wall_ns(self) -> int:
        """The base clock's wall time (may jump)."""
        return self.base.wall_ns()

    def sleep(self, seconds: float) -> None:
        """Sleep on the base clock."""
        self.base.sleep(seconds)
