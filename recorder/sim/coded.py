"""Arenas with many coded landmarks: distinct band codes, placed at random with spacing.

:func:`band_codes` lists codes in a fixed order (the 30 two-band codes of the six colours
first, then three-band codes); :func:`coded_landmarks` places ``n`` of them in an arena, at
least ``spacing_m`` apart and ``margin_m`` from the walls, and :func:`with_coded_landmarks`
puts them into a scenario document (``bslam experiment sweep n_landmarks``), reference pair
``L1``, ``L2`` (the first two), trajectory start moved off any landmark.
"""

from __future__ import annotations

import copy
import itertools
import math
from typing import Any

import numpy as np

from data_schemas.colors import COLOR_NAMES
from data_schemas.errors import ScenarioError

#: Two landmarks are at least this far apart (m) by default: room for the robot between them.
DEFAULT_SPACING_M = 0.25
#: Landmarks keep this far from the walls (m) by default.
DEFAULT_MARGIN_M = 0.08


def band_codes(n: int) -> list[tuple[str, ...]]:
    """``n`` distinct band codes (adjacent bands differ): two-band codes first, then three."""
    codes: list[tuple[str, ...]] = list(itertools.permutations(COLOR_NAMES, 2))
    codes += [c for c in itertools.product(COLOR_NAMES, repeat=3) if c[0] != c[1] and c[1] != c[2]]
    if n > len(codes):
        raise ScenarioError(f"at most {len(codes)} distinct band codes of 2-3 bands, asked {n}")
    return codes[:n]


def coded_landmarks(
    width_m: float,
    height_m: float,
    n: int,
    rng: np.random.Generator,
    *,
    spacing_m: float = DEFAULT_SPACING_M,
    margin_m: float = DEFAULT_MARGIN_M,
) -> list[dict[str, Any]]:
    """``n`` coded landmarks ``L1..Ln`` (scenario JSON) at random in a ``width x height`` arena.

    Raises
    ------
    ScenarioError
        The arena cannot hold ``n`` landmarks that far apart (after many tries).
    """
    placed: list[tuple[float, float]] = []
    for _ in range(200 * max(n, 1)):
        if len(placed) == n:
            break
        x = float(rng.uniform(margin_m, width_m - margin_m))
        y = float(rng.uniform(margin_m, height_m - margin_m))
        if all(math.hypot(x - a, y - b) >= spacing_m for a, b in placed):
            placed.append((x, y))
    if len(placed) < n:
        raise ScenarioError(
            f"cannot place {n} landmarks {spacing_m:g} m apart in a {width_m:g} x {height_m:g} m "
            "arena; use fewer landmarks or a bigger arena"
        )
    return [
        {"name": f"L{i + 1}", "x": round(x, 4), "y": round(y, 4), "bands": list(code)}
        for i, ((x, y), code) in enumerate(zip(placed, band_codes(n), strict=True))
    ]


def with_coded_landmarks(scenario: dict[str, Any], n: int, *, seed: int = 0) -> dict[str, Any]:
    """A copy of scenario JSON with ``n`` (>= 2) coded landmarks in its arena, reference L1, L2.

    The layout is drawn from ``seed``; the trajectory start moves to the free point nearest
    the arena centre if a landmark stands too close to it.
    """
    if n < 2:
        raise ScenarioError(f"a scenario needs at least 2 landmarks (the reference pair), got {n}")
    out = copy.deepcopy(scenario)
    width, height = float(out["arena"]["width"]), float(out["arena"]["height"])
    landmarks = coded_landmarks(width, height, n, np.random.default_rng(seed))
    out["landmarks"] = landmarks
    out["reference"] = ["L1", "L2"]
    start = out["trajectory"]["start"]
    clear = DEFAULT_SPACING_M / 2

    def free(x: float, y: float) -> bool:
        return all(math.hypot(x - lm["x"], y - lm["y"]) >= clear for lm in landmarks)

    if not free(start[0], start[1]):
        grid = [
            (width * (0.5 + dx / 20), height * (0.5 + dy / 20))
            for dx in range(-8, 9)
            for dy in range(-8, 9)
        ]
        grid.sort(key=lambda p: math.hypot(p[0] - width / 2, p[1] - height / 2))
        x, y = next(p for p in grid if free(*p))
        out["trajectory"]["start"] = [round(x, 4), round(y, 4), *start[2:]]
    return out
