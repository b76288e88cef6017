"""What bearing extraction reports per landmark, and how blobs become a report."""

from __future__ import annotations

import math
from dataclasses import dataclass

from pipeline.bearings.blobs import Blob


@dataclass(frozen=True)
class Detection:
    """One landmark in one frame.

    Attributes
    ----------
    name : str
        Landmark name from the catalog.
    visible : bool
        True if a blob of at least ``min_pixels`` pixels was found.
    bearing_rad : float or None
        Circular-mean bearing of the dominant blob, rad in [-pi, pi) relative to the robot
        heading; None when not visible (never a bearing for an absent landmark).
    width_rad : float
        Angular width of the dominant blob (0 if not visible).
    confidence : float
        0..1: ``(1 - exp(-n / (2 min_pixels))) * n / (n + n2)`` with ``n`` the dominant blob's
        pixels and ``n2`` the second blob's (0 if none): small or ambiguous blobs score low.
    n_pixels : int
        Pixels of the dominant blob (of the largest, too small one when not visible).
    n_blobs : int
        Blobs of this colour with at least ``min_pixels`` pixels.
    reason : str
        "" when visible; else why not.
    second_bearing_rad : float or None
        Bearing of the second-largest blob when ``n_blobs >= 2`` (reported, never averaged in).
    """

    name: str
    visible: bool
    bearing_rad: float | None
    width_rad: float
    confidence: float
    n_pixels: int
    n_blobs: int
    reason: str
    second_bearing_rad: float | None = None


def detection_from_blobs(
    name: str, blobs: list[Blob], largest: int, *, min_pixels: int, n_fringes: int = 0
) -> Detection:
    """Report for landmark ``name`` from its blobs (>= ``min_pixels``, largest first).

    ``largest`` is the pixel count of the largest run of its colour (any size); ``n_fringes``
    counts blobs already dropped as mixed-colour fringes of other landmarks.
    """
    if not blobs:
        if n_fringes:
            reason = f"only {n_fringes} mixed-colour fringe(s) beside other landmarks"
        elif largest:
            reason = f"too few pixels ({largest} < {min_pixels})"
        else:
            reason = "no pixels of its colour"
        return Detection(name, False, None, 0.0, 0.0, largest, 0, reason)
    top = blobs[0]
    second = blobs[1] if len(blobs) > 1 else None
    n2 = second.n_pixels if second else 0
    size_term = 1.0 - math.exp(-top.n_pixels / (2.0 * min_pixels))
    confidence = size_term * top.n_pixels / (top.n_pixels + n2)
    return Detection(
        name=name,
        visible=True,
        bearing_rad=top.bearing_rad,
        width_rad=top.width_rad,
        confidence=confidence,
        n_pixels=top.n_pixels,
        n_blobs=len(blobs),
        reason="",
        second_bearing_rad=second.bearing_rad if second else None,
    )
