"""Joint compatibility branch and bound (Neira and Tardos 2001) for landmarks that look alike.

A movement's detections of one shared class are assigned to the predicted bearings of the
class's named landmarks from its keyframes, all at once. The predictions are correlated: the
same landmark seen from both keyframes shares its position error, every landmark seen from one
keyframe shares that keyframe's pose error. A hypothesis ``H`` pairs detections with
predictions (each detection with at most one prediction of its own keyframe, each prediction
with at most one detection: a landmark at most once per keyframe); its joint innovation
``nu_H = wrap(z - h)`` has covariance ``S_H = P_H + r I`` (``P`` the predictions' joint
covariance, ``r`` the bearing noise variance of a detection) and ``H`` is jointly compatible
when every pair passes its own gate and ``D2_H = nu_H^T S_H^-1 nu_H`` is within the chi-square
gate of ``|H|`` degrees of freedom. The search returns the jointly compatible hypothesis with
the most pairs, the smallest ``D2_H`` among those; detections left out are spurious or of a
landmark not named yet, predictions left out are not seen.

``D2`` never decreases as pairs are added (a sub-vector's Mahalanobis norm under its marginal
covariance is at most the whole vector's), so a branch that cannot reach more pairs than the
best, or reaches as many only at a larger ``D2``, is cut. A pair of the answer is *ambiguous*
when a hypothesis as large without it is jointly compatible at a ``D2`` within ``margin`` of
the best: the data do not tell the two apart, and the caller should not trust either.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad
from pipeline.association.assign import Assignment, in_front

#: Probability mass inside the joint gate (and inside each pair's own gate).
GATE_P = 0.999
#: A pair is ambiguous when an assignment as large without it is within this ``D2``.
MARGIN_CHI2 = 9.0
#: Search nodes allowed per call; beyond it the best hypothesis found so far is returned.
MAX_NODES = 50_000


@functools.lru_cache(maxsize=256)
def chi2_quantile(dof: int, p: float = GATE_P) -> float:
    """Quantile ``p`` of the chi-square law with ``dof`` degrees of freedom."""
    # scipy.special only (scipy.stats costs ~0.9 s to import)
    from scipy.special import chdtri

    return float(chdtri(dof, 1.0 - p))


@dataclass(frozen=True)
class JointPredictions:
    """Predicted bearings of landmarks from keyframes and their joint covariance.

    Attributes
    ----------
    bearing_rad : (n,) float
        Predicted bearing of each (landmark, keyframe), robot frame, in [-pi, pi).
    cov_rad2 : (n, n) float
        Joint first-order covariance of the predictions (landmark and keyframe pose
        uncertainty; the detections' own noise is not in it), rad^2.
    landmark : (n,) int
        The landmark of each prediction.
    keyframe : (n,) int
        The keyframe of each prediction.
    """

    bearing_rad: NDArray[np.float64]
    cov_rad2: NDArray[np.float64]
    landmark: NDArray[np.int64]
    keyframe: NDArray[np.int64]


def joint_predictions(
    points_fl: NDArray[np.float64],
    covs_fl: NDArray[np.float64],
    origins_fl: NDArray[np.float64],
    headings_rad: NDArray[np.float64],
    pose_cov: NDArray[np.float64],
    visible: NDArray[np.bool_] | None = None,
) -> JointPredictions:
    """Bearings of ``L`` landmarks from ``K`` keyframes and their joint covariance, first order.

    Parameters
    ----------
    points_fl : (L, 2) float
        Landmark estimates, FL (independent of each other and of the poses).
    covs_fl : (L, 2, 2) float
        Their covariances, FL^2.
    origins_fl : (K, 2) float
        Keyframe positions, FL.
    headings_rad : (K,) float
        Keyframe headings, FL (bearings are relative to them).
    pose_cov : (3K, 3K) float
        Covariance of the keyframes' ``(x, y, heading)`` stacked keyframe by keyframe, FL
        frame (FL^2, FL rad, rad^2).
    visible : (K, L) bool or None
        Which (keyframe, landmark) to predict (None: all).

    Returns
    -------
    JointPredictions
        One prediction per visible (keyframe, landmark), keyframe by keyframe.
    """
    pts = np.asarray(points_fl, np.float64).reshape(-1, 2)
    covs = np.asarray(covs_fl, np.float64).reshape(-1, 2, 2)
    org = np.asarray(origins_fl, np.float64).reshape(-1, 2)
    head = np.asarray(headings_rad, np.float64).reshape(-1)
    n_l, n_k = len(pts), len(org)
    mask = np.ones((n_k, n_l), np.bool_) if visible is None else np.asarray(visible, np.bool_)
    kf, lm = np.nonzero(mask)
    d = pts[lm] - org[kf]
    r2 = np.maximum((d**2).sum(axis=1), 1e-12)
    j_pt = np.column_stack((-d[:, 1], d[:, 0])) / r2[:, None]  # d bearing / d point, (n, 2)
    # Jacobian with respect to every landmark (2L) then every pose (3K)
    n = len(kf)
    jac = np.zeros((n, 2 * n_l + 3 * n_k))
    rows = np.arange(n)
    jac[rows, 2 * lm] = j_pt[:, 0]
    jac[rows, 2 * lm + 1] = j_pt[:, 1]
    jac[rows, 2 * n_l + 3 * kf] = -j_pt[:, 0]
    jac[rows, 2 * n_l + 3 * kf + 1] = -j_pt[:, 1]
    jac[rows, 2 * n_l + 3 * kf + 2] = -1.0
    state = np.zeros((2 * n_l + 3 * n_k, 2 * n_l + 3 * n_k))
    for i in range(n_l):
        state[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] = covs[i]
    state[2 * n_l :, 2 * n_l :] = np.asarray(pose_cov, np.float64)
    cov = jac @ state @ jac.T
    bearing = wrap_rad(np.arctan2(d[:, 1], d[:, 0]) - head[kf])
    return JointPredictions(
        np.asarray(bearing, np.float64),
        0.5 * (cov + cov.T),
        lm.astype(np.int64),
        kf.astype(np.int64),
    )


def own_to_fl(cov_own: NDArray[np.float64], heading_rad: float) -> NDArray[np.float64]:
    """A keyframe pose covariance (3, 3) of ``(x, y, heading)`` in the keyframe's own frame
    (x ahead, y to the left) expressed in FL (the position part turned by the heading)."""
    c, s = math.cos(heading_rad), math.sin(heading_rad)
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    out: NDArray[np.float64] = turn @ np.asarray(cov_own, np.float64) @ turn.T
    return out


@dataclass(frozen=True)
class JointAssignment:
    """The answer of :func:`jcbb`.

    Attributes
    ----------
    pairs : list of (int, int)
        ``(prediction, detection)`` pairs of the largest jointly compatible hypothesis, sorted.
    d2 : float
        Its joint squared Mahalanobis distance (0 for no pair).
    ambiguous : list of (int, int)
        Pairs of ``pairs`` that an equally large jointly compatible hypothesis without them
        matches within ``margin`` (the data do not decide them).
    complete : bool
        False when the search stopped at its node budget (``pairs`` is then the best found).
    """

    pairs: list[tuple[int, int]] = field(default_factory=list)
    d2: float = 0.0
    ambiguous: list[tuple[int, int]] = field(default_factory=list)
    complete: bool = True


class _Search:
    """Branch and bound over detections in order; each detection takes a free prediction of
    its keyframe or none. ``D2`` is grown one pair at a time through the Cholesky factor of
    ``S_H`` (each step adds one row). A partial hypothesis is cut when its ``D2`` exceeds the
    gate of the largest hypothesis it can still grow into (the gate widens with each pair, so
    a hypothesis may pass its gate though a part of it does not pass the part's)."""

    def __init__(
        self,
        nu: NDArray[np.float64],
        s: NDArray[np.float64],
        cands: list[list[int]],
        gates: list[float],
        max_nodes: int,
    ) -> None:
        self.nu, self.s, self.cands, self.gates = nu, s, cands, gates
        self.max_nodes = max_nodes
        self.nodes = 0
        m = len(cands)
        # most pairs the detections from j on can still add
        self.left = [sum(1 for c in cands[j:] if c) for j in range(m + 1)]
        self.best: tuple[int, float, list[tuple[int, int]]] = (0, 0.0, [])
        self.found = False

    def run(
        self, floor: tuple[int, float], forbid: tuple[int, int] | None, first: bool
    ) -> tuple[int, float, list[tuple[int, int]]] | None:
        """Best hypothesis beating ``floor`` (more pairs, or as many at a smaller ``D2``),
        ``forbid`` never used; with ``first`` the first one found. None: there is none."""
        self.best = (floor[0], floor[1], [])
        self.found, self.forbid, self.first = False, forbid, first
        k = len(self.nu)
        self._chol = np.zeros((k, k))
        self._y = np.zeros(k)
        self._used = np.zeros(self.s.shape[0], np.bool_)
        self._rows: list[int] = []
        self._pairs: list[tuple[int, int]] = []
        self._walk(0, 0.0)
        return self.best if self.found else None

    def _better(self, n: int, d2: float) -> bool:
        return n > self.best[0] or (n == self.best[0] and d2 < self.best[1])

    def _walk(self, j: int, d2: float) -> None:
        self.nodes += 1
        if (self.found and self.first) or self.nodes > self.max_nodes:
            return
        n = len(self._pairs)
        if not self._better(n + self.left[j], d2):
            return  # cannot beat the best: D2 only grows
        if j == len(self.cands):
            if d2 <= self.gates[n]:
                self.best, self.found = (n, d2, list(self._pairs)), True
            return
        # the largest hypothesis this branch can still reach has the widest gate
        reach = self.gates[min(n + 1 + self.left[j + 1], len(self.gates) - 1)]
        for i in self.cands[j]:
            if self._used[i] or (i, j) == self.forbid:
                continue
            step = self._extend(i, j, n)
            if step is None or d2 + step > reach:
                continue
            self._used[i] = True
            self._pairs.append((i, j))
            self._rows.append(i)
            self._walk(j + 1, d2 + step)
            self._rows.pop()
            self._pairs.pop()
            self._used[i] = False
        self._walk(j + 1, d2)  # the detection left unpaired

    def _extend(self, i: int, j: int, n: int) -> float | None:
        """Add prediction ``i`` with detection ``j`` as row ``n`` of the Cholesky factor; the
        increase of ``D2`` (None: ``S_H`` would not be positive definite)."""
        chol, rows = self._chol, self._rows
        # the new row of the lower triangular factor: chol row = S[i, rows]
        row = np.linalg.solve(chol[:n, :n], self.s[i, rows]) if n else np.zeros(0)
        rest = float(self.s[i, i] - row @ row)
        if rest <= 1e-18:
            return None
        diag = math.sqrt(rest)
        y = (float(self.nu[i, j]) - float(row @ self._y[:n])) / diag
        chol[n, :n] = row
        chol[n, n] = diag
        chol[n, n + 1 :] = 0.0
        self._y[n] = y
        return y * y


def jcbb(
    pred_rad: NDArray[np.float64],
    cov_rad2: NDArray[np.float64],
    pred_keyframe: NDArray[np.int64],
    det_rad: NDArray[np.float64],
    det_keyframe: NDArray[np.int64],
    noise_var_rad2: float,
    *,
    p_gate: float = GATE_P,
    margin: float = MARGIN_CHI2,
    max_nodes: int = MAX_NODES,
) -> JointAssignment:
    """The largest jointly compatible assignment of detections to predictions.

    Parameters
    ----------
    pred_rad : (n,) float
        Predicted bearings, robot frame, rad.
    cov_rad2 : (n, n) float
        Their joint covariance, rad^2 (:func:`joint_predictions`).
    pred_keyframe : (n,) int
        The keyframe of each prediction.
    det_rad : (m,) float
        Detected bearings, robot frame, rad.
    det_keyframe : (m,) int
        The keyframe of each detection (a detection pairs only with its keyframe's
        predictions).
    noise_var_rad2 : float
        Variance of a detection's bearing noise, rad^2 (independent between detections).
    p_gate : float
        Probability inside each pair's gate (1 dof) and the joint gate (``|H|`` dof).
    margin : float
        A pair is ambiguous when an assignment as large without it has ``D2`` within this.
    max_nodes : int
        Search budget (nodes) of each search.

    Returns
    -------
    JointAssignment
        Pairs ``(prediction, detection)``, their ``D2``, the ambiguous pairs.
    """
    pred = np.asarray(pred_rad, np.float64).reshape(-1)
    det = np.asarray(det_rad, np.float64).reshape(-1)
    pk = np.asarray(pred_keyframe, np.int64).reshape(-1)
    dk = np.asarray(det_keyframe, np.int64).reshape(-1)
    s = np.asarray(cov_rad2, np.float64).reshape(len(pred), len(pred)) + noise_var_rad2 * np.eye(
        len(pred)
    )
    nu = np.asarray(wrap_rad(det[None, :] - pred[:, None]), np.float64).reshape(len(pred), len(det))
    var = np.maximum(np.diag(s), 1e-18)
    d2_one = nu**2 / var[:, None]
    own = (pk[:, None] == dk[None, :]) & (d2_one <= chi2_quantile(1, p_gate))
    # each detection's candidates, nearest first; detections with fewest candidates first
    cands = [[int(i) for i in np.argsort(d2_one[:, j]) if own[i, j]] for j in range(len(det))]
    order = sorted(range(len(det)), key=lambda j: (len(cands[j]) == 0, len(cands[j]), j))
    most = min(len(pred), len(det))
    gates = [0.0] + [chi2_quantile(k, p_gate) for k in range(1, most + 1)]
    search = _Search(nu[:, order], s, [cands[j] for j in order], gates, max_nodes)
    best = search.run((0, math.inf), None, first=False)
    complete = search.nodes <= max_nodes
    if best is None:
        return JointAssignment(complete=complete)
    n, d2, pairs = best
    ambiguous = []
    for i, jj in pairs:
        search.nodes = 0
        rival = search.run((n, d2 + margin), (i, jj), first=True)
        complete = complete and search.nodes <= max_nodes
        if rival is not None:
            ambiguous.append((i, order[jj]))
    return JointAssignment(
        sorted((i, order[jj]) for i, jj in pairs), d2, sorted(ambiguous), complete
    )


def assign_jointly(
    points_fl: NDArray[np.float64],
    covs_fl: NDArray[np.float64],
    visible: NDArray[np.bool_],
    origins_fl: NDArray[np.float64],
    headings_rad: NDArray[np.float64],
    pose_cov: NDArray[np.float64],
    det_rad: Sequence[NDArray[np.float64]],
    noise_var_rad2: float,
    *,
    margin: float = MARGIN_CHI2,
    range_fl: NDArray[np.float64] | None = None,
    range_std_fl: NDArray[np.float64] | None = None,
    in_line_rad: float = 0.0,
) -> list[Assignment]:
    """Assign the detections of one class at ``K`` keyframes to its ``L`` landmarks at once
    (:func:`jcbb`), as one :class:`~pipeline.association.assign.Assignment` per keyframe.

    Parameters
    ----------
    points_fl, covs_fl : (L, 2), (L, 2, 2) float
        The landmarks (FL, FL^2).
    visible : (K, L) bool
        Which landmark to predict at which keyframe (the others are left out of the answer).
    origins_fl, headings_rad, pose_cov : (K, 2), (K,), (3K, 3K) float
        The keyframes and their joint pose covariance (:func:`joint_predictions`).
    det_rad : K arrays (m_k,) float
        Each keyframe's detections, rad.
    noise_var_rad2 : float
        A detection's bearing noise variance, rad^2.
    margin : float
        Ambiguity margin (:func:`jcbb`); ambiguous pairs are contested, never used, with the
        landmarks whose gates hold their detections and the unpaired detections those gates
        hold.
    range_fl, range_std_fl : (K, L) float or None
        Predicted distances and their stds (FL; NaN: not trusted to hide another). When an
        ambiguous detection is the only one the landmarks whose gates hold it gate, and they
        are predicted in line (within ``in_line_rad``) with one clearly in front
        (:data:`~pipeline.association.assign.NEAR_RATIO`,
        :data:`~pipeline.association.assign.NEAR_SIGMAS`), that one takes it and hides the
        others.

    Returns
    -------
    list of Assignment
        Per keyframe; landmark indices into ``points_fl``; ``d2`` (L, m_k) each pair's own
        squared Mahalanobis distance (inf where not predicted).
    """
    vis = np.asarray(visible, np.bool_)
    jp = joint_predictions(points_fl, covs_fl, origins_fl, headings_rad, pose_cov, vis)
    dets = [np.asarray(d, np.float64).reshape(-1) for d in det_rad]
    det_all = np.concatenate([*dets, np.zeros(0)])
    det_k = np.concatenate(
        [np.full(len(d), k, np.int64) for k, d in enumerate(dets)] + [np.zeros(0, np.int64)]
    )
    start = np.concatenate(([0], np.cumsum([len(d) for d in dets])))
    got = jcbb(
        jp.bearing_rad, jp.cov_rad2, jp.keyframe, det_all, det_k, noise_var_rad2, margin=margin
    )
    var = np.diag(jp.cov_rad2) + noise_var_rad2
    nu = wrap_rad(det_all[None, :] - jp.bearing_rad[:, None])
    d2_all = (
        np.asarray(nu, np.float64).reshape(len(var), len(det_all)) ** 2
        / np.maximum(var, 1e-18)[:, None]
    )
    gate = chi2_quantile(1)
    # a search stopped at its budget may have missed a better assignment: trust none of it
    ambiguous = set(got.ambiguous) if got.complete else set(got.pairs)
    out = []
    for k, det in enumerate(dets):
        rows = np.flatnonzero(jp.keyframe == k)
        cols = np.arange(start[k], start[k + 1])
        lm = jp.landmark[rows]
        d2 = np.full((vis.shape[1], len(det)), np.inf)
        d2[lm] = d2_all[np.ix_(rows, cols)]
        pred = np.full(vis.shape[1], np.nan)
        pred[lm] = jp.bearing_rad[rows]
        ranges = None
        if range_fl is not None and range_std_fl is not None:
            ranges = (np.asarray(range_fl)[k], np.asarray(range_std_fl)[k])
        a = Assignment(d2=d2)
        sure = [(p, q) for p, q in got.pairs if jp.keyframe[p] == k and (p, q) not in ambiguous]
        unsure = [(p, q) for p, q in got.pairs if jp.keyframe[p] == k and (p, q) in ambiguous]
        a.pairs.extend((int(jp.landmark[p]), int(q - start[k])) for p, q in sure)
        taken = {i for i, _ in a.pairs}
        held = {j for _, j in a.pairs}
        contested_d: set[int] = set()
        contested_l: set[int] = set()
        for _, q in unsure:
            j = int(q - start[k])
            lms = [int(i) for i in lm[d2[lm, j] <= gate] if int(i) not in taken]
            front = _front_of(lms, j, d2 <= gate, pred, ranges, in_line_rad)
            if front is not None:
                a.pairs.append((front, j))
                a.hidden.extend((i, front) for i in lms if i != front)
                taken.update(lms)
                held.add(j)
                continue
            contested_d.add(j)
            contested_l.update(lms)
        # a landmark left unpaired though its gate holds a detection was not missed: that
        # detection went to another, or is contested
        contested_l.update(int(i) for i in lm if np.any(d2[i] <= gate))
        contested_l -= taken
        # the rivals' detections: unpaired ones a contested landmark's gate holds
        for i in contested_l:
            contested_d.update(int(j) for j in np.flatnonzero(d2[i] <= gate) if j not in held)
        a.contested_landmarks.extend(sorted(contested_l))
        a.contested_detections.extend(sorted(contested_d - held))
        a.missing.extend(int(i) for i in lm if int(i) not in taken | contested_l)
        a.unexplained.extend(j for j in range(len(det)) if j not in held | contested_d)
        a.pairs.sort()
        a.hidden.sort()
        out.append(a)
    return out


def _front_of(
    lms: list[int],
    j: int,
    gated: NDArray[np.bool_],
    pred_rad: NDArray[np.float64],
    ranges: tuple[NDArray[np.float64], NDArray[np.float64]] | None,
    in_line_rad: float,
) -> int | None:
    """Of landmarks ``lms`` whose gates hold detection ``j`` (``gated`` (L, m): whose gate
    holds which detection), the one clearly in front when they gate no other detection and
    are predicted (``pred_rad`` (L,)) in line; None: none is, or no distances (``ranges``:
    (L,) distances and stds, FL)."""
    if ranges is None or len(lms) < 2:
        return None
    if np.any(np.delete(gated[lms], j, axis=1)):
        return None  # they gate another detection too: not one blob
    ahead = in_front(ranges[0][lms], ranges[1][lms])
    if ahead is None:
        return None
    if float(np.abs(wrap_rad(pred_rad[lms] - pred_rad[lms[ahead]])).max()) > in_line_rad:
        return None
    return lms[ahead]
