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
    rng = np.random.default_rng(layout_seed)
    landmarks: list[dict[str, Any]] = [
        {"name": "L1", "x": REFERENCE_M[0][0], "y": REFERENCE_M[0][1], "color": "red"},
        {"name": "L2", "x": REFERENCE_M[1][0], "y": REFERENCE_M[1][1], "color": "green"},
    ]
    points = [REFERENCE_M[0], REFERENCE_M[1]]
    while len(points) < n + 2:
        x, y = rng.uniform(0.12, ARENA_M[0] - 0.12), rng.uniform(0.12, ARENA_M[1] - 0.12)
        clear = math.dist((x, y), START_M) >= spacing_m / 2  # not on the robot's start
        if clear and all(math.dist((x, y), p) >= spacing_m for p in points):
            points.append((x, y))
            landmarks.append(
                {"name": f"B{len(points) - 2}", "x": round(x, 4), "y": round(y, 4), "color": "blue"}
            )
    for lm in landmarks:
        lm.update({"radius": 0.01, "height": 0.15})
    return {
        "arena": {"width": ARENA_M[0], "height": ARENA_M[1]},
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
            "start": [0.8, 0.3, 0.0],
            "seed": layout_seed,
            "moves": moves,
            "distance": [0.2, 0.4],
        },
        "robot": {"radius": 0.03},
        "description": f"{n} identical blue landmarks and a distinct reference pair ({camera})",
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


def alike_arena(n: int, camera: str, size_m: tuple[float, float], *, seed: int) -> dict[str, Any]:
    """Scenario JSON: ``n`` identical blue landmarks drawn from ``seed`` at least 30 cm apart
    (15 cm from the walls) in an arena of ``size_m`` (width, height), the reference pair 60 cm
    apart at its middle, 30 movements of 30-60 cm from a quarter of its height."""
    w, h = size_m
    ref = ((w / 2 - 0.3, h / 2), (w / 2 + 0.3, h / 2))
    start = (w / 2, h / 4)
    rng = np.random.default_rng(seed)
    landmarks: list[dict[str, Any]] = [
        {"name": "L1", "x": ref[0][0], "y": ref[0][1], "color": "red"},
        {"name": "L2", "x": ref[1][0], "y": ref[1][1], "color": "green"},
    ]
    points = list(ref)
    while len(points) < n + 2:
        x, y = rng.uniform(0.15, w - 0.15), rng.uniform(0.15, h - 0.15)
        clear = math.dist((x, y), start) >= 0.15
        if clear and all(math.dist((x, y), p) >= 0.3 for p in points):
            points.append((x, y))
            landmarks.append(
                {"name": f"B{len(points) - 2}", "x": round(x, 4), "y": round(y, 4), "color": "blue"}
            )
    for lm in landmarks:
        lm.update({"radius": 0.01, "height": 0.15})
    return {
        "arena": {"width": w, "height": h},
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
            "start": [start[0], start[1], 0.0],
            "seed": seed,
            "moves": 30,
            "distance": [0.3, 0.6],
        },
        "robot": {"radius": 0.03},
        "description": f"{n} identical blue landmarks in a {w} x {h} m arena ({camera})",
    }
