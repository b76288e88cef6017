"""Landmark colour classes: the names a catalog may use and their nominal colours.

The names are the ``bslam.Color`` enum. Nominal BGR values are what the simulator paints and
what a real landmark should look like; the HSV ranges that *detect* them live with bearing
extraction in ``pipeline`` (overridable per landmark from the session metadata).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from itertools import pairwise
from typing import Any

#: name -> nominal colour (B, G, R), 0..255, as OpenCV orders channels.
NOMINAL_BGR: dict[str, tuple[int, int, int]] = {
    "red": (0, 0, 220),
    "green": (0, 200, 0),
    "blue": (220, 0, 0),
    "yellow": (0, 220, 220),
    "magenta": (220, 0, 220),
    "cyan": (220, 220, 0),
}

COLOR_NAMES: tuple[str, ...] = tuple(NOMINAL_BGR)


def class_label(color: str | None, bands: Sequence[str]) -> str:
    """The class a landmark is recognised by: its colour, or its band colours top to bottom.

    ``"red"`` for a single-colour landmark, ``"magenta-yellow"`` for a coded one. Landmarks with
    the same label look alike to the camera.
    """
    return "-".join(bands) if bands else str(color)


def appearance_problem(entry: Mapping[str, Any], *, name_only: bool = False) -> str | None:
    """Why a catalog/scenario landmark entry's ``color``/``bands`` keys are unusable, or None.

    A landmark has either ``"color"`` (one colour name) or ``"bands"`` (two or more colour
    names, top to bottom) or ``"tag"`` (a fiducial marker's id); the colour names themselves are
    checked by the schema. With
    ``name_only`` (a session without a camera) it may have neither: it is known by its name.
    """
    has_color, has_bands = "color" in entry, "bands" in entry
    if "tag" in entry:
        if has_color or has_bands:
            return "a fiducial ('tag') has no 'color' or 'bands'; give one of the three"
        return None
    if has_color and has_bands:
        return "give either 'color' (one colour) or 'bands' (colours top to bottom), not both"
    if not has_color and not has_bands and not name_only:
        return "needs 'color' (one colour) or 'bands' (two or more colours, top to bottom)"
    if has_bands and isinstance(entry["bands"], list):
        return band_problem(entry["bands"])
    return None


def band_problem(bands: Sequence[str]) -> str | None:
    """Why ``bands`` is not a band code (fewer than two bands, equal neighbours), or None."""
    if len(bands) < 2:
        return f"bands {list(bands)}: a coded landmark needs two or more bands"
    same = [a for a, b in pairwise(bands) if a == b]
    if same:
        return (
            f"bands {list(bands)}: two adjacent bands are both {same[0]!r}; adjacent bands "
            "must differ (they would look like one band)"
        )
    return None
