"""Time stamps: integer nanoseconds inside the code, ``{"sec", "nsec"}`` in messages (Foxglove)."""

from __future__ import annotations

from typing import TypedDict

NS_PER_S = 1_000_000_000


class Stamp(TypedDict):
    """Foxglove ``time``: whole seconds and nanoseconds (0..999,999,999)."""

    sec: int
    nsec: int


def stamp_from_ns(t_ns: int) -> Stamp:
    """Split a non-negative time in integer nanoseconds into a Foxglove stamp."""
    if t_ns < 0:
        raise ValueError(f"time stamps must be non-negative, got {t_ns} ns")
    sec, nsec = divmod(int(t_ns), NS_PER_S)
    return {"sec": sec, "nsec": nsec}


def ns_from_stamp(stamp: Stamp) -> int:
    """Join a Foxglove stamp back into integer nanoseconds."""
    return int(stamp["sec"]) * NS_PER_S + int(stamp["nsec"])
