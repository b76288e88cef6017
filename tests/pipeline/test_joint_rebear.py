"""``JointSlam.rebear``: once the log is processed, a landmark's bearings in the map are replaced
by the ones association with the final map gives it, and the map is solved again."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from data_schemas.paper_arena import PAPER_REFERENCE
from pipeline.joint.estimator import JointSlam
from pipeline.slam import MovementObservation
from pipeline.synthetic import SimulatedRun, simulate_bearings

EPS = math.radians(3.0)


def _processed(run: SimulatedRun) -> JointSlam:
    slam = JointSlam(
        list(run.landmarks_world),
        PAPER_REFERENCE,
        vision_error_rad=EPS,
        rng=np.random.default_rng(0),
        n_r=30,
        n_l=100,
    )
    for obs in run.observations:
        slam.process_movement(obs)
    return slam


def _shifted(o: MovementObservation, name: str, shift_rad: float) -> MovementObservation:
    """The movement with ``name``'s bearings turned by ``shift_rad`` at both keyframes."""
    return replace(
        o,
        bearings_o1_rad={n: b + shift_rad * (n == name) for n, b in o.bearings_o1_rad.items()},
        bearings_o2_rad={n: b + shift_rad * (n == name) for n, b in o.bearings_o2_rad.items()},
    )


def _bearings(run: SimulatedRun, name: str) -> list[tuple[int, int, float]]:
    return [
        (o.index, end, b[name])
        for o in run.observations
        for end, b in enumerate((o.bearings_o1_rad, o.bearings_o2_rad))
        if name in b
    ]


def _d2(slam: JointSlam, truth: NDArray[np.float64]) -> float:
    """Squared Mahalanobis distance of L3's true point from its estimate."""
    e = slam.estimates["L3"]
    v = e.mean_fl - truth
    return float(v @ np.linalg.solve(e.cov_fl, v))


def test_a_landmark_given_its_right_bearings_goes_where_they_meet() -> None:
    # L3's bearings turned by 0.9 eps at every keyframe (within the gate, as bearings of a
    # landmark beside it would be): the map puts it off its true point, far outside its region;
    # given its true bearings, it is where a map that had them from the start puts it, and its
    # true point is within its 99 % region again
    for seed in (5, 6, 8):
        run = simulate_bearings(10, np.random.default_rng(seed), eps_rad=EPS)
        wrong = replace(run, observations=[_shifted(o, "L3", 0.9 * EPS) for o in run.observations])
        slam, clean = _processed(wrong), _processed(run)
        truth = run.truth_fl()["L3"]
        l4_before = slam.estimates["L4"].mean_fl.copy()

        assert _d2(slam, truth) > 9.21, seed  # chi-square 2 dof, 99 %: the shifted map is wrong
        given = _bearings(run, "L3")
        slam.rebear({"L3": given, "L99": [(0, 0, 0.0)]})  # not a landmark: ignored
        assert _d2(slam, truth) <= 9.21, seed
        back, first = slam.estimates["L3"], clean.estimates["L3"]
        assert np.hypot(*(back.mean_fl - first.mean_fl)) < 0.25 * np.sqrt(first.cov_fl.trace())
        assert slam.bearing_scatter["L3"][0] == len(given)
        # the other landmarks keep their bearings and move by the map's change alone
        assert slam.bearing_scatter["L4"][0] == clean.bearing_scatter["L4"][0]
        moved = np.hypot(*(slam.estimates["L4"].mean_fl - l4_before))
        assert moved < 3.0 * np.sqrt(clean.estimates["L4"].cov_fl.trace()), seed


def test_nothing_changes_for_a_landmark_not_in_the_map() -> None:
    run = simulate_bearings(6, np.random.default_rng(3), eps_rad=EPS)
    slam = _processed(run)
    before = {n: e.mean_fl.copy() for n, e in slam.estimates.items()}
    slam.rebear({"L99": [(0, 0, 0.1)]})
    assert {n: e.mean_fl.tolist() for n, e in slam.estimates.items()} == {
        n: m.tolist() for n, m in before.items()
    }
