"""Blobs of a size no landmark of their class can have: a floor, a wall, a poster.

A landmark ``width_m`` wide seen from ``r`` metres (to its centre) spans ``2 asin(width_m / 2
r)``; between the nearest and farthest distances it can be seen from (the catalog's
``range_m``) its blob's angular width lies between the values at ``r_max`` and ``r_min``. A blob
much wider than the widest landmark of its class at ``r_min`` (a floor or a wall of its colour
runs across many columns) or much narrower than the narrowest at ``r_max`` is rejected, with
the reason. The tolerances cover a blob's edge pixels and bridged gaps (a blob is measured in
whole bins) and a landmark half hidden.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from data_schemas.session import LandmarkSpec
from pipeline.bearings.blobs import Blob

#: A blob may be this much wider than the widest landmark of its class at ``r_min`` ...
WIDE_FACTOR = 1.25
#: ... or this share of the narrowest at ``r_max`` (a landmark half hidden still passes) ...
NARROW_FACTOR = 0.5
#: ... each give or take this many bins (edge pixels, bridged gaps).
SLACK_BINS = 3


@dataclass(frozen=True)
class SizeGate:
    """Angular widths (rad) a blob of one class may have: ``lo_rad <= width <= hi_rad``.

    ``why_wide`` / ``why_narrow`` describe the bound for a rejection's reason.
    """

    lo_rad: float
    hi_rad: float
    why_wide: str
    why_narrow: str

    def problem(self, blob: Blob) -> str | None:
        """Why ``blob`` cannot be a landmark of the class, or None."""
        width = math.degrees(blob.width_rad)
        if blob.width_rad > self.hi_rad:
            return f"{width:.1f} deg wide: wider than {self.why_wide}"
        if blob.width_rad < self.lo_rad:
            return f"{width:.1f} deg wide: narrower than {self.why_narrow}"
        return None


def size_gate(
    specs: Sequence[LandmarkSpec], range_m: tuple[float, float] | None, bin_width_rad: float
) -> SizeGate | None:
    """The gate of a class whose landmarks are ``specs``; None unless every one has a width and
    ``range_m`` (nearest, farthest distance, m) is given."""
    widths = [s.width_m for s in specs]
    if range_m is None or not widths or any(w is None for w in widths):
        return None
    known = [float(w) for w in widths if w is not None]
    r_min, r_max = range_m
    wide, narrow = max(known), min(known)
    hi = _angular_width(wide, r_min)
    lo = _angular_width(narrow, r_max)
    return SizeGate(
        lo_rad=NARROW_FACTOR * lo - SLACK_BINS * bin_width_rad,
        hi_rad=WIDE_FACTOR * hi + SLACK_BINS * bin_width_rad,
        why_wide=f"{wide:g} m at {r_min:g} m ({math.degrees(hi):.1f} deg)",
        why_narrow=f"{narrow:g} m at {r_max:g} m ({math.degrees(lo):.1f} deg)",
    )


def _angular_width(width_m: float, range_m: float) -> float:
    """Angle (rad) a cylinder ``width_m`` across spans from ``range_m`` to its centre."""
    return 2.0 * math.asin(min(1.0, 0.5 * width_m / range_m))
