"""Landmark colour classes: the names a catalog may use and their nominal colours.

The names are the ``bslam.Color`` enum. Nominal BGR values are what the simulator paints and
what a real landmark should look like; the HSV ranges that *detect* them live with bearing
extraction in ``pipeline`` (overridable per landmark from the session metadata).
"""

from __future__ import annotations

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
