"""Joint compatibility branch and bound: the same answer as enumerating every assignment on
small random cases, joint predictions against finite differences, and hand-made cases where
each pair's own gate is ambiguous and joint compatibility is not."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.stats import chi2

from pipeline.association import assign
from pipeline.association.jcbb import assign_jointly, jcbb, joint_predictions

DEG = math.pi / 180.0
P = 0.999


def _enumerate(
    pred: NDArray[np.float64],
    cov: NDArray[np.float64],
    pk: NDArray[np.int64],
    det: NDArray[np.float64],
    dk: NDArray[np.int64],
    noise: float,
) -> list[tuple[int, float, frozenset[tuple[int, int]]]]:
    """Every jointly compatible assignment (each pair within its own 1-dof gate, the whole
    within the |H|-dof gate, one-to-one, same keyframe): (size, D2, pairs)."""
    gate = [float(chi2.ppf(P, k)) if k else 0.0 for k in range(len(det) + 1)]
    # a detection pairs with none or a prediction of its keyframe
    options = [[None, *np.flatnonzero(pk == dk[j]).tolist()] for j in range(len(det))]
    out: list[tuple[int, float, frozenset[tuple[int, int]]]] = []
    for choice in itertools.product(*options):
        used = [i for i in choice if i is not None]
        if len(set(used)) != len(used):
            continue
        pairs = [(i, j) for j, i in enumerate(choice) if i is not None]
        if not pairs:
            out.append((0, 0.0, frozenset()))
            continue
        rows = [i for i, _ in pairs]
        nu = np.array([(det[j] - pred[i] + math.pi) % (2 * math.pi) - math.pi for i, j in pairs])
        s = cov[np.ix_(rows, rows)] + noise * np.eye(len(rows))
        if any(nu[k] ** 2 / s[k, k] > gate[1] for k in range(len(rows))):
            continue
        d2 = float(nu @ np.linalg.inv(s) @ nu)
        if d2 <= gate[len(rows)]:
            out.append((len(rows), d2, frozenset(pairs)))
    return out


def _random_case(
    rng: np.random.Generator,
) -> tuple[
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.int64],
    NDArray[np.float64],
    NDArray[np.int64],
    float,
]:
    """A few landmarks seen from two keyframes with uncertain poses; detections from the truth
    (some missed) plus spurious ones."""
    n_l = int(rng.integers(1, 4))
    pts = rng.uniform(-1.5, 1.5, (n_l, 2))
    covs = np.array([np.diag(rng.uniform(0.0005, 0.02, 2)) for _ in range(n_l)])
    origins = np.array([[0.0, 0.0], [0.3, 0.1]])
    headings = np.array([0.1, 0.1])
    pose_cov = np.diag(np.tile([1e-4, 1e-4, (rng.uniform(1.0, 6.0) * DEG) ** 2], 2))
    pose_cov[2, 5] = pose_cov[5, 2] = 0.8 * pose_cov[2, 2]  # one movement: headings correlated
    jp = joint_predictions(pts, covs, origins, headings, pose_cov)
    noise = (1.0 * DEG) ** 2
    true = rng.multivariate_normal(
        jp.bearing_rad, jp.cov_rad2 + noise * np.eye(len(jp.bearing_rad))
    )
    seen = rng.random(len(true)) < 0.8
    extra = int(rng.integers(0, 3))
    near = rng.integers(0, len(true), extra)
    det = np.concatenate((true[seen], jp.bearing_rad[near] + rng.normal(0.0, 6.0 * DEG, extra)))
    dk = np.concatenate((jp.keyframe[seen], jp.keyframe[near]))
    perm = rng.permutation(len(det))
    return jp.bearing_rad, jp.cov_rad2, jp.keyframe, det[perm], dk[perm], noise


@pytest.mark.parametrize("seed", range(6))
def test_jcbb_finds_the_assignment_enumeration_finds(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for _ in range(25):
        pred, cov, pk, det, dk, noise = _random_case(rng)
        every = _enumerate(pred, cov, pk, det, dk, noise)
        size = max(n for n, _, _ in every)
        d2, pairs = min((d, p) for n, d, p in every if n == size)
        got = jcbb(pred, cov, pk, det, dk, noise)
        assert got.complete
        assert len(got.pairs) == size
        assert got.d2 == pytest.approx(d2, rel=1e-9, abs=1e-12)
        assert frozenset(got.pairs) == pairs
        ambiguous = {
            p
            for p in pairs
            if any(n == size and q != pairs and p not in q and d < d2 + 9.0 for n, d, q in every)
        }
        assert set(got.ambiguous) == ambiguous


def test_joint_predictions_match_finite_differences() -> None:
    rng = np.random.default_rng(7)
    pts = rng.uniform(-2.0, 2.0, (3, 2))
    covs = np.array(
        [
            [[0.02, 0.005], [0.005, 0.01]],
            [[0.001, 0.0], [0.0, 0.03]],
            [[0.01, -0.004], [-0.004, 0.01]],
        ]
    )
    origins = np.array([[0.1, -0.2], [0.5, 0.2]])
    headings = np.array([0.4, -2.9])
    a = rng.normal(size=(6, 6))
    pose_cov = 1e-3 * (a @ a.T)
    visible = np.array([[True, False, True], [True, True, True]])
    jp = joint_predictions(pts, covs, origins, headings, pose_cov, visible)

    def bearings(x: NDArray[np.float64]) -> NDArray[np.float64]:
        p, poses = x[:6].reshape(3, 2), x[6:].reshape(2, 3)
        return np.array(
            [
                math.atan2(p[lm, 1] - poses[k, 1], p[lm, 0] - poses[k, 0]) - poses[k, 2]
                for k in range(2)
                for lm in range(3)
                if visible[k, lm]
            ]
        )

    x0 = np.concatenate((pts.ravel(), np.column_stack((origins, headings)).ravel()))
    h = 1e-6
    jac = np.column_stack(
        [(bearings(x0 + h * e) - bearings(x0 - h * e)) / (2 * h) for e in np.eye(len(x0))]
    )
    state = np.zeros((12, 12))
    for i in range(3):
        state[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] = covs[i]
    state[6:, 6:] = pose_cov
    want = bearings(x0)
    assert np.allclose(np.cos(jp.bearing_rad - want), 1.0)
    assert jp.cov_rad2 == pytest.approx(jac @ state @ jac.T, rel=1e-6, abs=1e-12)
    assert list(jp.keyframe) == [0, 0, 1, 1, 1] and list(jp.landmark) == [0, 2, 0, 1, 2]


def _heading_case(gap_rad: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Two landmarks ``gap_rad`` apart seen from one keyframe whose heading is uncertain
    (std 0.2 rad); the predictions and their joint covariance (well placed landmarks: the
    heading dominates)."""
    pred = np.array([0.0, gap_rad])
    cov = np.full((2, 2), 0.2**2) + np.diag([1e-6, 1e-6])
    return pred, cov


def test_a_common_heading_error_decides_what_each_gate_cannot() -> None:
    # the keyframe turned 0.15 rad more than planned: both detections shifted by +0.15
    pred, cov = _heading_case(0.3)
    det = np.array([0.45, 0.15])
    noise = (0.5 * DEG) ** 2
    one = assign(pred, np.sqrt(np.diag(cov) + noise), det)
    assert one.pairs == [] and sorted(one.contested_landmarks) == [0, 1]  # each gate: both fit
    got = jcbb(pred, cov, np.zeros(2, np.int64), det, np.zeros(2, np.int64), noise)
    # hand: the swapped pairing's innovations (0.45, -0.15) differ by 0.6 rad with only the
    # noise (0.7 deg) between them: D2 ~ 0.36 / (2 * 7.6e-5) >> the 2-dof gate
    assert got.pairs == [(0, 1), (1, 0)] and got.ambiguous == []
    s = cov + noise * np.eye(2)
    nu = np.array([0.15, 0.15])
    assert got.d2 == pytest.approx(float(nu @ np.linalg.solve(s, nu)), rel=1e-9)


def test_a_spurious_blob_in_a_gate_is_told_apart_by_the_other_landmark() -> None:
    # landmark 0 has two blobs at +-0.15 rad, equally far for its own gate; landmark 1's blob
    # (1 rad away) says the heading is off by +0.15: the blob at -0.15 is the spurious one
    # (with it, landmark 1 would be at 0.85, where nothing is seen)
    pred, cov = _heading_case(1.0)
    det = np.array([-0.15, 0.15, 1.15])
    noise = (0.5 * DEG) ** 2
    one = assign(pred, np.sqrt(np.diag(cov) + noise), det)
    assert 0 in one.contested_landmarks  # its own gate holds both blobs equally
    got = jcbb(pred, cov, np.zeros(2, np.int64), det, np.zeros(3, np.int64), noise)
    assert got.pairs == [(0, 1), (1, 2)] and got.ambiguous == []


def test_a_landmark_seen_from_both_keyframes_ties_its_two_detections() -> None:
    # one landmark at (1, 0), uncertain across the rays (30 cm in y, 1 cm in x); from the
    # second keyframe two blobs fit its wide gate, but only one fits the y its
    # first-keyframe blob fixes (y = 0.2; the other blob would need y = -0.3)
    pts = np.array([[1.0, 0.0]])
    covs = np.array([[[0.0001, 0.0], [0.0, 0.09]]])
    origins = np.array([[0.0, 0.0], [0.0, 0.5]])
    jp = joint_predictions(pts, covs, origins, np.zeros(2), np.zeros((6, 6)))
    noise = (0.5 * DEG) ** 2
    det = np.array([math.atan2(0.2, 1.0), math.atan2(-0.8, 1.0), math.atan2(-0.3, 1.0)])
    dk = np.array([0, 1, 1])
    one = assign(jp.bearing_rad[1:], np.sqrt(jp.cov_rad2[1, 1] + noise)[None], det[1:])
    assert one.pairs == [] and one.contested_landmarks == [0]  # O2's gate alone: both fit
    got = jcbb(jp.bearing_rad, jp.cov_rad2, jp.keyframe, det, dk, noise)
    assert got.pairs == [(0, 0), (1, 2)] and got.ambiguous == []


def test_two_detections_in_one_gate_with_nothing_to_tell_them_apart_are_ambiguous() -> None:
    pred = np.array([30.0 * DEG])
    cov = np.array([[(3.0 * DEG) ** 2]])
    got = jcbb(
        pred, cov, np.zeros(1, np.int64), np.radians([27.0, 33.5]), np.zeros(2, np.int64), 0.0
    )
    assert len(got.pairs) == 1 and got.ambiguous == got.pairs


def test_no_prediction_no_detection_and_no_candidate_give_empty_answers() -> None:
    empty = np.zeros(0, np.int64)
    assert (
        jcbb(
            np.zeros(0), np.zeros((0, 0)), empty, np.array([0.1]), np.zeros(1, np.int64), 1e-4
        ).pairs
        == []
    )
    assert (
        jcbb(
            np.array([0.1]), np.eye(1) * 1e-4, np.zeros(1, np.int64), np.zeros(0), empty, 1e-4
        ).pairs
        == []
    )
    far = jcbb(
        np.array([0.1]),
        np.eye(1) * 1e-4,
        np.zeros(1, np.int64),
        np.array([2.0]),
        np.zeros(1, np.int64),
        1e-4,
    )
    assert far.pairs == [] and far.d2 == 0.0
    # a detection pairs only with its own keyframe's predictions
    other = jcbb(
        np.array([0.1]),
        np.eye(1) * 1e-4,
        np.zeros(1, np.int64),
        np.array([0.1]),
        np.ones(1, np.int64),
        1e-4,
    )
    assert other.pairs == []


def test_one_keyframe_assignment_says_missing_unexplained_contested_and_hidden() -> None:
    # from (0, 0), heading 0: landmarks at 40 deg (1.5, 0.5 and 0.9 FL away, in line), one at
    # -60 deg (not seen) and one at 100 deg with two blobs 3 deg either side of it
    deg = np.radians([40.0, 41.0, 39.5, -60.0, 100.0])
    dist = np.array([1.5, 0.5, 0.9, 1.0, 1.0])
    pts = dist[:, None] * np.column_stack((np.cos(deg), np.sin(deg)))
    covs = np.array([1e-8 * np.eye(2)] * 5)
    det = np.radians([40.6, 97.0, 103.0, -150.0])
    pose_cov = np.diag([0.0, 0.0, (0.1 * DEG) ** 2])
    std = np.full((1, 5), 0.01)
    (a,) = assign_jointly(
        pts,
        covs,
        np.ones((1, 5), bool),
        np.zeros((1, 2)),
        np.zeros(1),
        pose_cov,
        [det],
        (2.0 * DEG) ** 2,
        range_fl=dist[None, :],
        range_std_fl=std,
        in_line_rad=3.0 * DEG,
    )
    assert a.pairs == [(1, 0)] and a.hidden == [(0, 1), (2, 1)]
    assert a.missing == [3] and a.unexplained == [3]
    assert a.contested_landmarks == [4] and a.contested_detections == [1, 2]
    # the landmark at -60 deg left out of the prediction (not visible there): neither missing
    # nor anything else
    (b,) = assign_jointly(
        pts,
        covs,
        np.array([[True, True, True, False, True]]),
        np.zeros((1, 2)),
        np.zeros(1),
        pose_cov,
        [det],
        (2.0 * DEG) ** 2,
    )
    assert b.missing == [] and 3 not in b.contested_landmarks
    # without distances nothing hides: the in-line landmarks contest their blob
    assert sorted(b.contested_landmarks) == [0, 1, 2, 4] and b.contested_detections == [0, 1, 2]


def test_detections_with_no_landmark_visible_are_all_unexplained() -> None:
    (a,) = assign_jointly(
        np.array([[1.0, 0.0]]),
        np.array([1e-4 * np.eye(2)]),
        np.zeros((1, 1), bool),
        np.zeros((1, 2)),
        np.zeros(1),
        np.zeros((3, 3)),
        [np.array([0.1, 0.2])],
        1e-4,
    )
    assert a.pairs == [] and a.unexplained == [0, 1] and a.missing == []


def test_a_search_stopped_at_its_budget_says_so() -> None:
    pred = np.radians([0.0, 10.0, 20.0, 30.0])
    cov = np.eye(4) * (1.0 * DEG) ** 2
    det = pred + np.radians([0.3, -0.2, 0.1, 0.4])
    kf = np.zeros(4, np.int64)
    assert jcbb(pred, cov, kf, det, kf, 1e-6).complete
    cut = jcbb(pred, cov, kf, det, kf, 1e-6, max_nodes=3)
    assert not cut.complete and len(cut.pairs) < 4  # 3 nodes reach no full assignment
