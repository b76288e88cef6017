"""Gated one-to-one assignment: clear matches, refusals to guess, occlusion: the landmark
clearly in front takes the blob, the ones behind are hidden; a movement's assignment and the
detections it leaves for the hypotheses."""

from __future__ import annotations

import math

import numpy as np

from pipeline.association import (
    MovementAssignment,
    MovementAssociation,
    assign,
    assign_movement,
    predict_bearings,
    ray_point_cov,
)
from pipeline.association.predict import BearingModel, predict_named
from pipeline.estimate import LandmarkEstimate

DEG = math.pi / 180.0


def test_clear_predictions_are_matched_one_to_one_in_any_order() -> None:
    rng = np.random.default_rng(1)
    pred = np.radians([-150.0, -60.0, 10.0, 95.0, 170.0])
    for _ in range(50):
        order = rng.permutation(5)
        det = pred[order] + rng.normal(0.0, 1.0 * DEG, 5)
        a = assign(pred, np.full(5, 2.0 * DEG), det)
        assert sorted(a.pairs) == sorted((int(order[j]), j) for j in range(5))
        assert not (a.missing or a.unexplained or a.contested_landmarks)


def test_seam_does_not_break_a_match() -> None:
    a = assign(np.radians([179.5]), np.array([2.0 * DEG]), np.radians([-179.0]))
    assert a.pairs == [(0, 0)]


def test_two_detections_in_one_gate_are_contested_not_forced() -> None:
    a = assign(np.radians([30.0]), np.array([3.0 * DEG]), np.radians([27.0, 33.5]))
    assert a.pairs == [] and a.contested_landmarks == [0]
    assert sorted(a.contested_detections) == [0, 1]


def test_one_detection_between_two_overlapping_landmarks_is_not_given_to_either() -> None:
    # one landmark hidden behind the other: a single blob where both are predicted
    a = assign(np.radians([40.0, 41.0]), np.full(2, 2.0 * DEG), np.radians([40.6]))
    assert a.pairs == []
    assert sorted(a.contested_landmarks) == [0, 1] and a.contested_detections == [0]


def test_a_landmark_clearly_in_front_takes_the_one_blob_and_hides_those_behind() -> None:
    # three landmarks in line along 40 deg, one blob: only the nearest can show there
    a = assign(
        np.radians([40.0, 41.0, 39.5]),
        np.full(3, 2.0 * DEG),
        np.radians([40.6]),
        range_fl=np.array([1.5, 0.5, 0.9]),
        range_std_fl=np.full(3, 0.05),
        in_line_rad=3.0 * DEG,
    )
    assert a.pairs == [(1, 0)] and a.hidden == [(0, 1), (2, 1)]
    assert not (a.contested_landmarks or a.contested_detections or a.missing)


def test_occlusion_needs_a_clear_lead_in_distance_from_trusted_landmarks_in_line() -> None:
    det = np.radians([40.6])
    for pred_deg, std_deg, range_fl, range_std_fl in [
        ([40.0, 41.0], 2.0, [0.5, 0.55], [0.01, 0.01]),  # nearly as far: either may be in front
        ([40.0, 41.0], 2.0, [0.5, 1.0], [0.2, 0.2]),  # a lead (0.5) under 3 stds of it (0.28)
        ([40.0, 41.0], 2.0, [0.5, math.nan], [0.01, 0.01]),  # one landmark not trusted to judge
        ([38.0, 43.5], 3.0, [0.5, 1.5], [0.01, 0.01]),  # predicted 5.5 deg apart: not in line
    ]:
        a = assign(
            np.radians(pred_deg),
            np.full(2, std_deg * DEG),
            det,
            range_fl=np.array(range_fl),
            range_std_fl=np.array(range_std_fl),
            in_line_rad=3.0 * DEG,
        )
        assert a.pairs == [] and not a.hidden and sorted(a.contested_landmarks) == [0, 1]


def test_distances_do_not_decide_between_two_blobs() -> None:
    # two blobs, each in both gates: which landmark made which is not a matter of occlusion
    a = assign(
        np.radians([30.0, 31.0]),
        np.full(2, 2.0 * DEG),
        np.radians([29.5, 31.5]),
        range_fl=np.array([0.5, 1.5]),
        range_std_fl=np.full(2, 0.01),
    )
    assert a.pairs == [] and not a.hidden


def test_missing_and_unexplained_are_reported_apart() -> None:
    a = assign(np.radians([0.0, 90.0]), np.full(2, 2.0 * DEG), np.radians([0.5, -120.0]))
    assert a.pairs == [(0, 0)] and a.missing == [1] and a.unexplained == [1]


def test_a_crowded_group_keeps_the_pairs_every_alternative_rejects() -> None:
    # landmark 0 sees a clear detection; landmark 1's gate also reaches it, its own is far off
    pred = np.radians([0.0, 6.0])
    a = assign(pred, np.full(2, 2.0 * DEG), np.radians([0.2, 6.3, 3.1]))
    assert a.pairs == []  # 3.1 deg sits in both gates: both landmarks contested
    b = assign(pred, np.full(2, 1.0 * DEG), np.radians([0.2, 6.3]))
    assert b.pairs == [(0, 0), (1, 1)]


def test_predicted_std_grows_with_the_landmark_covariance_and_shrinks_with_range() -> None:
    pts = np.array([[1.0, 0.0], [3.0, 0.0]])
    covs = np.array([np.eye(2) * 0.01, np.eye(2) * 0.01])
    b, std = predict_bearings(np.zeros(2), 0.0, pts, covs)
    assert np.allclose(b, 0.0)
    assert math.isclose(std[0], 0.1, rel_tol=1e-9) and math.isclose(std[1], 0.1 / 3, rel_tol=1e-9)
    _, std2 = predict_bearings(np.zeros(2), 0.0, pts, covs, bearing_var_rad=0.01)
    assert np.all(std2 > std)


def test_ray_point_cov_matches_the_spread_of_noisy_intersections() -> None:
    rng = np.random.default_rng(4)
    origins = np.array([[0.0, 0.0], [1.0, 0.0]])
    point = np.array([0.4, 1.2])
    sigma = 0.5 * DEG
    cov = ray_point_cov(point, origins, sigma)
    d = point - origins
    base = np.arctan2(d[:, 1], d[:, 0])
    fixes = []
    for _ in range(4000):
        ang = base + rng.normal(0.0, sigma, 2)
        u = np.column_stack((np.cos(ang), np.sin(ang)))
        t = np.linalg.solve(np.column_stack((u[0], -u[1])), origins[1] - origins[0])
        fixes.append(origins[0] + t[0] * u[0])
    emp = np.cov(np.array(fixes).T)
    assert np.linalg.norm(emp - cov) <= 0.1 * np.linalg.norm(cov)


def test_a_movement_assignment_leaves_the_unexplained_and_contested_detections_free() -> None:
    # one movement from (0, 0) to (1, 0), heading 0; blue#1 at (0.5, 1) and blue#2 at
    # (0.5, -1) sharp, blue#3 far and vague (1 FL std at 4 FL); bearings by hand
    eps = 3.0 * DEG
    model = BearingModel(eps)
    sharp, vague = 1e-6 * np.eye(2), np.eye(2)
    known = [
        ("blue#1", LandmarkEstimate(np.array([0.5, 1.0]), sharp)),
        ("blue#2", LandmarkEstimate(np.array([0.5, -1.0]), sharp)),
        ("blue#3", LandmarkEstimate(np.array([3.0, 3.0]), vague)),
    ]
    b1_at_o1 = math.atan2(1.0, 0.5)
    b1_at_o2, b2_at_o2 = math.atan2(1.0, -0.5), math.atan2(-1.0, -0.5)
    dets = {
        "blue": (
            np.array([b1_at_o1, 150.0 * DEG]),  # blue#1, and a blob no name explains
            np.array([b1_at_o2, b2_at_o2 + 0.6 * DEG, b2_at_o2 - 0.6 * DEG]),  # two at blue#2
        ),
        "red": (np.zeros(0), np.zeros(0)),
    }
    predicted = {
        "blue": tuple(
            predict_named(known, np.array(o), 0.0, 0.0, model, trusted=())
            for o in ((0.0, 0.0), (1.0, 0.0))
        )
    }
    record = assign_movement(4, dets, predicted, in_line_rad=eps)  # type: ignore[arg-type]
    assert record.free("blue") == ([1], [1, 2])
    assert record.free("red") == ([], [])
    assert MovementAssignment(4, dets).free("blue") == ([], [])  # not placed: nothing free
    out = MovementAssociation(4, assignment=record)
    out.report()
    assert out.names == {
        "blue": (["blue#1", None], ["blue#1", None, None]),
        "red": ([], []),
    }
    assert out.bearings_o1_rad == {"blue#1": b1_at_o1}
    assert out.bearings_o2_rad == {"blue#1": b1_at_o2}
    assert out.outcomes == {
        "blue#1": ["seen", "seen"],
        "blue#2": ["missed", "contested"],
        "blue#3": ["vague", "vague"],
    }
    assert {"blue#3@O1", "blue#3@O2", "blue@O2"} <= set(out.unresolved)
    assert "blue#2@O1" in out.not_visible
