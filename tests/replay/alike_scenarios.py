"""Scenarios of landmarks that look alike: ``n`` identical blue landmarks and a distinct
reference pair (red L1, green L2), for association tests and measurements."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

ARENA_M = (1.6, 1.2)
REFERENCE_M = ((0.55, 0.6), (1.05, 0.6))
START_M = (0.8, 0.3)
CAMERAS: dict[str, dict[str, Any]] = {
    "unwrapped": {"model": "unwrapped", "width": 960, "height": 160},
    "omni": {"model": "omni", "width": 480, "height": 480},
}


def alike_scenario(
    n: int, camera: str, *, layout_seed: int, moves: int = 20, spacing_m: float = 0.22
) -> dict[str, Any]:
    """Scenario JSON: ``n`` blue landmarks drawn from ``layout_seed`` at least ``spacing_m``
    apart (and from the reference pair and the arena's walls), camera ``"unwrapped"`` or
    ``"omni"``."""
    return _scenario(
        n,
        camera,
        ARENA_M,
        REFERENCE_M,
        START_M,
        seed=layout_seed,
        spacing_m=spacing_m,
        wall_m=0.12,
        start_clear_m=spacing_m / 2,
        moves=moves,
        distance_m=(0.2, 0.4),
        description=f"{n} identical blue landmarks and a distinct reference pair ({camera})",
    )


def alike_arena(n: int, camera: str, size_m: tuple[float, float], *, seed: int) -> dict[str, Any]:
    """Scenario JSON: ``n`` identical blue landmarks drawn from ``seed`` at least 30 cm apart
    (15 cm from the walls) in an arena of ``size_m`` (width, height), the reference pair 60 cm
    apart at its middle, 30 movements of 30-60 cm from a quarter of its height."""
    w, h = size_m
    return _scenario(
        n,
        camera,
        size_m,
        ((w / 2 - 0.3, h / 2), (w / 2 + 0.3, h / 2)),
        (w / 2, h / 4),
        seed=seed,
        spacing_m=0.3,
        wall_m=0.15,
        start_clear_m=0.15,
        moves=30,
        distance_m=(0.3, 0.6),
        description=f"{n} identical blue landmarks in a {w} x {h} m arena ({camera})",
    )


def _scenario(
    n: int,
    camera: str,
    arena_m: tuple[float, float],
    reference_m: tuple[tuple[float, float], tuple[float, float]],
    start_m: tuple[float, float],
    *,
    seed: int,
    spacing_m: float,
    wall_m: float,
    start_clear_m: float,
    moves: int,
    distance_m: tuple[float, float],
    description: str,
) -> dict[str, Any]:
    """The scenario document: ``n`` blue landmarks drawn from ``seed``, ``spacing_m`` apart,
    ``wall_m`` from the walls and ``start_clear_m`` from the robot's start."""
    rng = np.random.default_rng(seed)
    landmarks: list[dict[str, Any]] = [
        {"name": "L1", "x": reference_m[0][0], "y": reference_m[0][1], "color": "red"},
        {"name": "L2", "x": reference_m[1][0], "y": reference_m[1][1], "color": "green"},
    ]
    points = [reference_m[0], reference_m[1]]
    while len(points) < n + 2:
        x = rng.uniform(wall_m, arena_m[0] - wall_m)
        y = rng.uniform(wall_m, arena_m[1] - wall_m)
        clear = math.dist((x, y), start_m) >= start_clear_m  # not on the robot's start
        if clear and all(math.dist((x, y), p) >= spacing_m for p in points):
            points.append((x, y))
            landmarks.append(
                {"name": f"B{len(points) - 2}", "x": round(x, 4), "y": round(y, 4), "color": "blue"}
            )
    for lm in landmarks:
        lm.update({"radius": 0.01, "height": 0.15})
    return {
        "arena": {"width": arena_m[0], "height": arena_m[1]},
        "landmarks": landmarks,
        "reference": ["L1", "L2"],
        "camera": {
            **CAMERAS[camera],
            "bearing_noise_deg": 1.0,
            "pixel_noise": 2.0,
            "lighting": True,
        },
        "vision_error_deg": 3.0,
        "trajectory": {
            "start": [start_m[0], start_m[1], 0.0],
            "seed": seed,
            "moves": moves,
            "distance": list(distance_m),
        },
        "robot": {"radius": 0.03},
        "description": description,
    }


def coded_wide_reference(moves: int = 10) -> dict[str, Any]:
    """The built-in ``coded_3x2`` (20 coded landmarks, 3 x 2 m, unwrapped 960 x 160) with L2 and
    L5 swapped: the same layout and codes, the reference pair 1.18 m apart (46 cm built in); the
    trajectory ``moves`` movements long (10 built in)."""
    from recorder.sim.scenario import builtin_scenario

    doc = builtin_scenario("coded_3x2").to_dict()
    swap = {"L2": "L5", "L5": "L2"}
    for lm in doc["landmarks"]:
        lm["name"] = swap.get(lm["name"], lm["name"])
    doc["trajectory"]["moves"] = moves
    doc["description"] = (
        f"coded_3x2 with L2 and L5 swapped (a 1.18 m reference baseline), {moves} movements"
    )
    return doc
