"""What bearing extraction reports per landmark class and per landmark, and how blobs become a
report."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from pipeline.bearings.blobs import Blob


@dataclass(frozen=True)
class Detection:
    """One landmark in one frame.

    A derived log carries the fields the ``bslam.Detection`` schema declares (None ones left
    out); ``second_bearing_rad``, ``blobs`` and ``ambiguous`` stay in memory.

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
    blobs : tuple of Blob
        Every blob of the landmark's class (its colour or band code), largest first: what an
        association step matches against the map when several landmarks share a class.
    ambiguous : bool
        True if other catalog landmarks share this landmark's class: then no bearing is given
        (``visible`` False, ``reason`` says so) until something associates the blobs.
    rejected : tuple of (Blob, str)
        Blobs of its class rejected (a size no landmark of the class can have, cut by the
        image's edge), each with the reason (:attr:`ClassSightings.rejected`).
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
    blobs: tuple[Blob, ...] = ()
    ambiguous: bool = False
    rejected: tuple[tuple[Blob, str], ...] = ()


@dataclass(frozen=True)
class ClassSightings:
    """Every blob of one landmark class (a colour or a band code) in one frame.

    Attributes
    ----------
    label : str
        The class: ``"red"`` or ``"magenta-yellow"``.
    landmarks : tuple of str
        Catalog landmarks of this class (more than one: the class is ambiguous).
    blobs : tuple of Blob
        Blobs of at least ``min_pixels`` pixels, largest first: bearing, angular width, pixels.
    largest : int
        Pixel count of the largest run of the class (any size; 0 if none).
    n_fringes : int
        Blobs dropped as mixed-colour fringes of other landmarks.
    coded : bool
        True for a band code.
    rejected : tuple of (Blob, str)
        Blobs of a size no landmark of the class can have (:mod:`pipeline.bearings.size_gate`),
        each with the reason; not in ``blobs``.
    """

    label: str
    landmarks: tuple[str, ...]
    blobs: tuple[Blob, ...]
    largest: int
    n_fringes: int = 0
    coded: bool = False
    rejected: tuple[tuple[Blob, str], ...] = ()


def detection_of(name: str, sightings: ClassSightings, *, min_pixels: int) -> Detection:
    """Report for landmark ``name`` from the blobs of its class.

    A class of one landmark: its largest blob (see :func:`detection_from_blobs`). A class
    several landmarks share: no bearing, the reason names them (never the largest blob's
    bearing, which may belong to another landmark).
    """
    blobs = list(sightings.blobs)
    if len(sightings.landmarks) == 1:
        det = detection_from_blobs(
            name, blobs, sightings.largest, min_pixels=min_pixels, n_fringes=sightings.n_fringes
        )
        if sightings.coded and not det.visible and not sightings.largest:
            det = replace(det, reason=f"band code {sightings.label} not read")
        if not det.visible and sightings.rejected:
            n, why = len(sightings.rejected), sightings.rejected[0][1]
            det = replace(det, reason=f"no blob of a landmark's size ({n} rejected; {why})")
        return replace(det, blobs=sightings.blobs, rejected=sightings.rejected)
    others = ", ".join(n for n in sightings.landmarks if n != name)
    reason = (
        f"ambiguous: class {sightings.label} is shared with {others} "
        f"({len(blobs)} blob(s) seen); no association"
    )
    n_pixels = blobs[0].n_pixels if blobs else sightings.largest
    return Detection(
        name,
        False,
        None,
        0.0,
        0.0,
        n_pixels,
        len(blobs),
        reason,
        None,
        sightings.blobs,
        True,
        sightings.rejected,
    )


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
