"""Gated one-to-one assignment of detections to predicted landmarks, refusing to guess.

Cost of pairing landmark ``i`` with detection ``j``: the squared Mahalanobis distance
``d2 = (wrap(b_j - pred_i) / std_i)^2`` (one degree of freedom). A pair is plausible when
``d2 <= gate``. Landmarks and detections split into groups linked by plausible pairs; a group of
one landmark and one detection is a match; in a larger group the best one-to-one assignment
(scipy's ``linear_sum_assignment``; leaving a landmark or a detection alone costs ``gate``) is
kept only for pairs whose every alternative costs at least ``margin`` more; the rest of the
group is contested (reported, never used).

Occlusion: when the predicted distances are given, a group of landmarks that all gate a single
detection, none of them sure, and are predicted in line (within ``in_line_rad`` of one bearing)
is seen along that bearing. Only the nearest can show there, so when one is clearly the
nearest (:data:`NEAR_RATIO`, :data:`NEAR_SIGMAS`) it takes the detection and the others are
hidden behind it.

Per movement, :func:`assign_movement` assigns each shared class's detections at O1 and at O2 to
its named landmarks' predictions (:func:`pipeline.association.predict.predict_named`) and
returns the :class:`MovementAssignment` the hypotheses take next: the detections, and which
of them no name took.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad
from pipeline.association.predict import GATE_CHI2, Predicted

#: A pairing is unique when every alternative assignment costs this much more (chi-square units).
MARGIN_CHI2 = 9.0
#: Occlusion: the nearest landmark of a group takes its one detection when it is at most this
#: share of the next one's distance...
NEAR_RATIO = 0.8
#: ... and nearer by this many stds of the two distances' difference.
NEAR_SIGMAS = 3.0
_BIG = 1e9


@dataclass(frozen=True)
class Assignment:
    """What :func:`assign` decided for one keyframe and one class.

    Attributes
    ----------
    pairs : list of (int, int)
        ``(landmark index, detection index)`` matches.
    missing : list of int
        Landmarks with no plausible detection (hidden, out of range, or not seen).
    unexplained : list of int
        Detections no landmark explains (candidates for new landmarks).
    contested_landmarks, contested_detections : list of int
        Landmarks and detections of groups the assignment could not resolve.
    hidden : list of (int, int)
        ``(landmark, landmark in front of it)``: landmarks hidden behind a nearer one.
    d2 : (n, m) float
        The Mahalanobis costs.
    """

    pairs: list[tuple[int, int]] = field(default_factory=list)
    missing: list[int] = field(default_factory=list)
    unexplained: list[int] = field(default_factory=list)
    contested_landmarks: list[int] = field(default_factory=list)
    contested_detections: list[int] = field(default_factory=list)
    hidden: list[tuple[int, int]] = field(default_factory=list)
    d2: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 0)))


def _solve(d2: NDArray[np.float64], gate: float) -> tuple[float, list[tuple[int, int]]]:
    """Best assignment with "alone" options at cost ``gate``; its cost and its pairs."""
    # imported here: scipy.optimize costs about 0.6 s, and only look-alike landmarks need it
    from scipy.optimize import linear_sum_assignment

    n, m = d2.shape
    big = np.full((n + m, m + n), _BIG)
    big[:n, :m] = np.where(d2 <= gate, d2, _BIG)
    big[:n, m:] = np.where(np.eye(n, dtype=bool), gate, _BIG)
    big[n:, :m] = np.where(np.eye(m, dtype=bool), gate, _BIG)
    big[n:, m:] = 0.0
    rows, cols = linear_sum_assignment(big)
    pairs = [(int(r), int(c)) for r, c in zip(rows, cols, strict=True) if r < n and c < m]
    return float(big[rows, cols].sum()), pairs


def _groups(plausible: NDArray[np.bool_]) -> list[tuple[list[int], list[int]]]:
    """Connected groups (landmarks, detections) of the plausible-pair graph."""
    n, m = plausible.shape
    seen_l = np.zeros(n, bool)
    seen_d = np.zeros(m, bool)
    out = []
    for start in range(n):
        if seen_l[start]:
            continue
        lms, dets, todo = [start], [], [start]
        seen_l[start] = True
        while todo:
            i = todo.pop()
            for j in np.flatnonzero(plausible[i] & ~seen_d):
                seen_d[j] = True
                dets.append(int(j))
                for k in np.flatnonzero(plausible[:, j] & ~seen_l):
                    seen_l[k] = True
                    lms.append(int(k))
                    todo.append(int(k))
        out.append((sorted(lms), sorted(dets)))
    out.extend(([], [int(j)]) for j in np.flatnonzero(~seen_d))
    return out


def in_front(range_fl: NDArray[np.float64], range_std_fl: NDArray[np.float64]) -> int | None:
    """Index of the landmark clearly nearer than every other one (None: none is)."""
    if range_fl.size < 2 or not np.all(np.isfinite(range_fl)):
        return None
    a, b = (int(i) for i in np.argsort(range_fl)[:2])
    gap = range_fl[b] - range_fl[a]
    if range_fl[a] > NEAR_RATIO * range_fl[b] or gap < NEAR_SIGMAS * math.hypot(
        range_std_fl[a], range_std_fl[b]
    ):
        return None
    return a


def _in_line(pred_rad: NDArray[np.float64], front: int, tol_rad: float) -> bool:
    """Whether every predicted bearing is within ``tol_rad`` of the one in front's."""
    return float(np.abs(wrap_rad(pred_rad - pred_rad[front])).max()) <= tol_rad


def assign(
    pred_rad: NDArray[np.float64],
    pred_std_rad: NDArray[np.float64],
    det_rad: NDArray[np.float64],
    *,
    gate: float = GATE_CHI2,
    margin: float = MARGIN_CHI2,
    range_fl: NDArray[np.float64] | None = None,
    range_std_fl: NDArray[np.float64] | None = None,
    in_line_rad: float = 0.0,
) -> Assignment:
    """Assign detections (m,) to predicted bearings (n,) with stds (n,), one-to-one.

    ``range_fl`` and ``range_std_fl`` (n,) are the landmarks' predicted distances and their
    stds (FL; NaN: not known well enough to judge occlusion); without them no landmark hides
    another. Landmarks are in line when their predicted bearings are within ``in_line_rad``
    of the nearest one's.

    Returns
    -------
    Assignment
        Matches, landmarks with no plausible detection, detections no landmark explains,
        landmarks hidden behind a nearer one, and the contested rest.
    """
    pred = np.asarray(pred_rad, np.float64).reshape(-1)
    std = np.maximum(np.asarray(pred_std_rad, np.float64).reshape(-1), 1e-9)
    det = np.asarray(det_rad, np.float64).reshape(-1)
    d2 = (wrap_rad(det[None, :] - pred[:, None]) / std[:, None]) ** 2
    plausible = d2 <= gate
    out = Assignment(d2=d2)
    for lms, dets in _groups(plausible):
        if not dets:
            out.missing.extend(lms)
        elif not lms:
            out.unexplained.extend(dets)
        elif len(lms) == 1 and len(dets) == 1:
            out.pairs.append((lms[0], dets[0]))
        else:
            sub = d2[np.ix_(lms, dets)]
            best, pairs = _solve(sub, gate)
            sure = []
            for i, j in pairs:
                alt = sub.copy()
                alt[i, j] = _BIG
                if _solve(alt, gate)[0] - best >= margin:
                    sure.append((i, j))
            if not sure and len(dets) == 1 and range_fl is not None and range_std_fl is not None:
                front = in_front(np.asarray(range_fl)[lms], np.asarray(range_std_fl)[lms])
                if front is not None and _in_line(pred[lms], front, in_line_rad):
                    out.pairs.append((lms[front], dets[0]))
                    out.hidden.extend((k, lms[front]) for k in lms if k != lms[front])
                    continue
            out.pairs.extend((lms[i], dets[j]) for i, j in sure)
            out.contested_landmarks.extend(
                lms[i] for i in range(len(lms)) if i not in {p[0] for p in sure}
            )
            out.contested_detections.extend(
                dets[j] for j in range(len(dets)) if j not in {p[1] for p in sure}
            )
    out.pairs.sort()
    out.hidden.sort()
    return out


#: One class's detections at O1 and at O2: bearings (m1,) and (m2,), rad.
Detections = tuple[NDArray[np.float64], NDArray[np.float64]]


@dataclass(frozen=True)
class MovementAssignment:
    """One movement's detections of shared classes and what the assignment decided: the
    record the hypothesis step takes after the assignment.

    Attributes
    ----------
    index : int
        The movement.
    detections_rad : dict label -> (array (m1,), array (m2,))
        Each shared class's detections at O1 and at O2 (rad), in the order given.
    predicted : dict label -> (Predicted, Predicted)
        The class's named landmarks as predicted at O1 and at O2 (only classes detected in a
        placed movement).
    decided : dict label -> (Assignment, Assignment)
        Their assignment at O1 and at O2 (indices into ``predicted`` names and detections).
    """

    index: int
    detections_rad: dict[str, Detections]
    predicted: dict[str, tuple[Predicted, Predicted]] = field(default_factory=dict)
    decided: dict[str, tuple[Assignment, Assignment]] = field(default_factory=dict)

    def free(self, label: str) -> tuple[list[int], list[int]]:
        """The detections of ``label`` at O1 and at O2 that no name took: unexplained, or
        contested (they may still be a landmark not named yet); none when the movement was
        not placed or the class was not detected."""
        decided = self.decided.get(label)
        if decided is None:
            return [], []
        a1, a2 = decided
        return sorted(a1.unexplained + a1.contested_detections), sorted(
            a2.unexplained + a2.contested_detections
        )


def assign_movement(
    index: int,
    detections_rad: Mapping[str, Detections],
    predicted: Mapping[str, tuple[Predicted, Predicted]],
    *,
    in_line_rad: float,
) -> MovementAssignment:
    """Assign one movement's detections of each predicted class to its named landmarks, at O1
    and at O2 (:func:`assign`; landmarks predicted within ``in_line_rad`` of each other are in
    line).

    Parameters
    ----------
    index : int
        The movement.
    detections_rad : dict label -> (array (m1,), array (m2,))
        Each shared class's detections at O1 and at O2 (rad).
    predicted : dict label -> (Predicted, Predicted)
        The named landmarks of each class detected, predicted at O1 and at O2.

    Returns
    -------
    MovementAssignment
        The detections and, per class of ``predicted``, the assignment at each keyframe.
    """
    decided = {
        label: (
            _assign_at(ends[0], detections_rad[label][0], in_line_rad),
            _assign_at(ends[1], detections_rad[label][1], in_line_rad),
        )
        for label, ends in predicted.items()
    }
    return MovementAssignment(index, dict(detections_rad), dict(predicted), decided)


def _assign_at(p: Predicted, det_rad: NDArray[np.float64], in_line_rad: float) -> Assignment:
    """:func:`assign` at one keyframe."""
    return assign(
        p.bearing_rad,
        p.std_rad,
        det_rad,
        range_fl=p.range_fl,
        range_std_fl=p.range_std_fl,
        in_line_rad=in_line_rad,
    )
