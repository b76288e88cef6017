"""Coloured clutter for test frames: patches of landmark colours that are not landmarks."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from data_schemas.colors import NOMINAL_BGR


def add_clutter(
    image_bgr: NDArray[np.uint8],
    rng: np.random.Generator,
    *,
    n: int,
    areas_px: tuple[int, ...],
    colors: tuple[str, ...] = tuple(NOMINAL_BGR),
    region: tuple[slice, slice] = (slice(None), slice(None)),
) -> NDArray[np.uint8]:
    """A copy of ``image_bgr`` with ``n`` solid rectangles of nominal landmark colours.

    Each patch has an area drawn from ``areas_px`` (any w x h factorisation of it) and a colour
    drawn from ``colors``; it lies inside ``region`` (rows, columns) of the image.
    """
    out = image_bgr.copy()
    rows = range(out.shape[0])[region[0]]
    cols = range(out.shape[1])[region[1]]
    for _ in range(n):
        area = int(rng.choice(areas_px))
        shapes = [(sw, area // sw) for sw in range(1, area + 1) if area % sw == 0]
        sw, sh = shapes[int(rng.integers(len(shapes)))]
        x = cols.start + int(rng.integers(0, len(cols) - sw + 1))
        y = rows.start + int(rng.integers(0, len(rows) - sh + 1))
        out[y : y + sh, x : x + sw] = NOMINAL_BGR[colors[int(rng.integers(len(colors)))]]
    return out
