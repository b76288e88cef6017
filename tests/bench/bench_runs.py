"""Simulated runs the joint-estimator benchmarks share (:mod:`pipeline.synthetic`, no images)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from pipeline.synthetic import SimulatedRun, scatter_landmarks, simulate_bearings

#: The reference pair of the scattered arenas (world, m).
SCATTER_REFERENCE = {"L1": (1.2, 1.7), "L2": (1.8, 1.7)}


def scattered_run(
    n_movements: int, n_landmarks: int, rng: np.random.Generator, eps_rad: float, gap_m: float
) -> SimulatedRun:
    """Bearings of ``n_movements`` movements of 0.3-0.6 m in a 3 x 2 m arena whose
    ``n_landmarks`` (the reference pair :data:`SCATTER_REFERENCE` among them) are scattered at
    least ``gap_m`` apart; bearing errors of std ``eps_rad / 3`` within ``eps_rad``. Draws the
    landmarks, then the run, from ``rng``."""
    pts = scatter_landmarks(rng, SCATTER_REFERENCE, n_landmarks, (0.05, 0.05), (2.95, 1.95), gap_m)
    return simulate_bearings(
        n_movements,
        rng,
        eps_rad=eps_rad,
        sigma_frac=1 / 3,
        landmarks_world=pts,
        arena_m=(3.0, 2.0),
        move_m=(0.3, 0.6),
    )


def with_distances(run: SimulatedRun, rng: np.random.Generator) -> SimulatedRun:
    """The run with each movement's driven distance: its true length with 2% noise (``rng``)."""
    lengths = np.hypot(*(run.o2_world - run.o1_world).T)
    obs = [
        replace(o, distance_m=float(d * (1.0 + rng.normal(0.0, 0.02))))
        for o, d in zip(run.observations, lengths, strict=True)
    ]
    return replace(run, observations=obs)
