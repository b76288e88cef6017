"""Arena families for measuring calibration: scenario documents drawn per seed.

Each family stresses the joint map in one way; :func:`family_scenario` draws one run's scenario
(layout, trajectory and camera from the seed; the cameras alternate with the seed's parity):

- ``paper``: the paper's arena (1.05 x 0.68 m, four landmarks, 1 deg noise), the paper's
  255 x 176 panorama or the omnidirectional camera; ``paper_noise_free`` the same without
  added bearing noise.
- ``noise_free``: a random arena (:func:`pipeline.synthetic.random_arena`), no added bearing
  noise (pixel columns, pixel noise and thresholding only).
- ``long``: a 4.5 x 1 m corridor, six landmarks along it, 20 movements of 0.3-0.6 m.
- ``close_pairs``: three pairs of landmarks 6-10 cm apart (each hides the other from some
  views) beside a distinct reference pair, 2 x 1.5 m.
- ``coded``: eight coded (two-band) landmarks in 2.5 x 2 m, 15 movements.
- ``wide_sparse``: a 4 x 3 m arena with four landmarks, 12 movements of 0.3-0.7 m.
- ``varied``: :func:`replay.experiments.arenas.arena_scenario` (up to 3 x 2 m, 4-8 landmarks,
  0-1.5 deg noise).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from data_schemas.colors import COLOR_NAMES
from replay.experiments.arenas import CAMERAS, arena_scenario

#: The paper's camera (its unwrapped 255 x 176 panorama).
PAPER_CAMERA = {"model": "unwrapped", "width": 255, "height": 176}
FAMILIES = (
    "paper",
    "paper_noise_free",
    "noise_free",
    "long",
    "close_pairs",
    "coded",
    "wide_sparse",
    "varied",
)


def _start(
    rng: np.random.Generator, w: float, h: float, pts: list[tuple[float, float]]
) -> list[float]:
    """A start point inside the arena and clear of every landmark."""
    for _ in range(1000):
        s = rng.uniform([0.15, 0.15], [w - 0.15, h - 0.15])
        if all(math.dist(s, p) > 0.15 for p in pts):
            break
    return [round(float(s[0]), 4), round(float(s[1]), 4)]


def _scatter(
    rng: np.random.Generator, n: int, w: float, h: float, spacing_m: float
) -> list[tuple[float, float]]:
    pts: list[tuple[float, float]] = []
    while len(pts) < n:
        p = (float(rng.uniform(0.1, w - 0.1)), float(rng.uniform(0.1, h - 0.1)))
        if all(math.dist(p, q) >= spacing_m for q in pts):
            pts.append(p)
    return pts


def _doc(
    description: str,
    size_m: tuple[float, float],
    landmarks: list[dict[str, Any]],
    camera: dict[str, Any],
    noise_deg: float,
    trajectory: dict[str, Any],
) -> dict[str, Any]:
    return {
        "description": description,
        "arena": {"width": size_m[0], "height": size_m[1]},
        "landmarks": landmarks,
        "reference": ["L1", "L2"],
        "camera": {**camera, "bearing_noise_deg": noise_deg},
        "vision_error_deg": 3.0,
        "trajectory": trajectory,
    }


def _colored(pts: list[tuple[float, float]]) -> list[dict[str, Any]]:
    return [
        {"name": f"L{i + 1}", "x": round(x, 4), "y": round(y, 4), "color": COLOR_NAMES[i]}
        for i, (x, y) in enumerate(pts)
    ]


def family_scenario(family: str, seed: int) -> dict[str, Any]:
    """One run's scenario document of ``family`` (see the module docstring), drawn from ``seed``."""
    rng = np.random.default_rng([seed, FAMILIES.index(family)])
    camera = CAMERAS[seed % 2]
    if family == "varied":
        return arena_scenario(seed, camera, 10)
    if family == "noise_free":
        doc = arena_scenario(seed, camera, 10)
        doc["camera"]["bearing_noise_deg"] = 0.0
        doc["description"] += ", no added bearing noise"
        return doc
    if family in ("paper", "paper_noise_free"):
        pts = [(0.375, 0.55), (0.675, 0.55), (0.20, 0.20), (0.85, 0.18)]
        traj = {"start": [0.52, 0.34], "moves": 10, "distance": [0.10, 0.25], "seed": seed}
        if seed % 2 == 0:
            camera = PAPER_CAMERA
        noise = 0.0 if family == "paper_noise_free" else 1.0
        return _doc("paper arena", (1.05, 0.68), _colored(pts), camera, noise, traj)
    if family == "long":
        w, h = 4.5, 1.0
        along = sorted(_scatter(rng, 6, w, h, 0.4))
        pts = [along[2], along[3], along[0], along[1], along[4], along[5]]  # reference mid-way
        traj = {"start": _start(rng, w, h, pts), "moves": 20, "distance": [0.3, 0.6], "seed": seed}
        return _doc("long corridor 4.5 x 1 m", (w, h), _colored(pts), camera, 1.0, traj)
    if family == "close_pairs":
        w, h = 2.0, 1.5
        centres = _scatter(rng, 5, w - 0.2, h - 0.2, 0.45)
        pts = [(x + 0.1, y + 0.1) for x, y in centres[:2]]
        for cx, cy in centres[2:]:
            gap = float(rng.uniform(0.06, 0.10))
            a = float(rng.uniform(0.0, math.pi))
            dx, dy = 0.5 * gap * math.cos(a), 0.5 * gap * math.sin(a)
            pts += [(cx + 0.1 - dx, cy + 0.1 - dy), (cx + 0.1 + dx, cy + 0.1 + dy)]
        codes = (["red", "green"], ["blue", "yellow"])  # one pair coded
        lms = [
            *_colored(pts[:6]),
            *(
                {"name": f"L{7 + i}", "x": round(x, 4), "y": round(y, 4), "bands": code}
                for i, ((x, y), code) in enumerate(zip(pts[6:], codes, strict=True))
            ),
        ]
        traj = {"start": _start(rng, w, h, pts), "moves": 15, "distance": [0.2, 0.4], "seed": seed}
        return _doc("three close pairs, 2 x 1.5 m", (w, h), lms, camera, 1.0, traj)
    if family == "coded":
        from recorder.sim.coded import coded_landmarks

        w, h = 2.5, 2.0
        lms = coded_landmarks(w, h, 8, rng)
        pts = [(lm["x"], lm["y"]) for lm in lms]
        traj = {"start": _start(rng, w, h, pts), "moves": 15, "distance": [0.25, 0.5], "seed": seed}
        cam = {"model": "unwrapped", "width": 960, "height": 160} if seed % 2 == 0 else camera
        return _doc("eight coded landmarks, 2.5 x 2 m", (w, h), lms, cam, 1.0, traj)
    if family == "wide_sparse":
        w, h = 4.0, 3.0
        pts = _scatter(rng, 4, w, h, 0.8)
        traj = {"start": _start(rng, w, h, pts), "moves": 12, "distance": [0.3, 0.7], "seed": seed}
        return _doc("wide sparse 4 x 3 m, four landmarks", (w, h), _colored(pts), camera, 1.0, traj)
    raise ValueError(f"unknown family {family!r}; choose from {', '.join(FAMILIES)}")
