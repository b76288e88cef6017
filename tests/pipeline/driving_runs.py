"""A simulated drive fed to the driving estimator sample by sample, as the runner feeds a log:
shared by the driving tests."""

from __future__ import annotations

import math

import numpy as np

from pipeline.driving.estimator import DrivingOptions, DrivingSlam
from pipeline.driving.simulate import Arena, DrivingRun, DrivingSpec, arenas, simulate_drive


def run_drive(
    arena: str, seed: int, duration_s: float, options: DrivingOptions | None = None
) -> tuple[Arena, DrivingRun, DrivingSlam]:
    """Simulate ``duration_s`` seconds in ``arena`` (seed ``seed``, 2 deg bearing bound) and map
    it: every bearing set before each odometry sample, then the sample; the map finished."""
    a = arenas()[arena]
    run = simulate_drive(a, DrivingSpec(duration_s=duration_s), np.random.default_rng(seed))
    slam = DrivingSlam(
        list(a.landmarks_world),
        a.reference,
        vision_error_rad=math.radians(2.0),
        rng=np.random.default_rng(seed),
        options=options,
    )
    sets = iter(run.bearing_sets)
    pending = next(sets, None)
    for t, pose in zip(run.t_ns, run.odometry, strict=True):
        while pending is not None and pending[0] <= t:
            slam.bearings(*pending)
            pending = next(sets, None)
        slam.odometry(int(t), pose)
    slam.finish()
    return a, run, slam
