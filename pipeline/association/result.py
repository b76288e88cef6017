"""What association did for one movement (:class:`MovementAssociation`), and the names it gives."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from pipeline.association.assign import Assignment, MovementAssignment
from pipeline.association.predict import Predicted
from pipeline.association.support import Outcome
from pipeline.geometry import MovementPose


def slot_name(label: str, k: int) -> str:
    """The name of the ``k``-th confirmed landmark of class ``label`` (``red#1``)."""
    return f"{label}#{k}"


def deg_text(x_rad: float) -> str:
    """An angle (rad) as text in degrees (``"3.1 deg"``)."""
    return f"{math.degrees(x_rad):.1f} deg"


@dataclass
class MovementAssociation:
    """What association did for one movement.

    Attributes
    ----------
    index : int
        The movement.
    bearings_o1_rad, bearings_o2_rad : dict name -> float
        Bearings given to named landmarks of shared classes at O1 and O2 (rad).
    names : dict label -> (list, list)
        Per class, the name given to each detection at O1 and at O2 (None: not associated),
        in the order of the detections passed in.
    confirmed : list of str
        Landmarks named with this movement.
    history : dict name -> list of (movement, end, bearing_rad)
        Bearings of the landmarks named with this movement from earlier movements (for an
        estimator that can take them late).
    unresolved : dict key -> str
        Ambiguities not resolved (key: a landmark name or a class label, with the keyframe).
    not_visible : dict name -> str
        Named landmarks predicted but not detected (hidden behind another, out of range).
    outcomes : dict name -> list of str
        Per named landmark predicted at this movement's keyframes, what became of each
        prediction (:data:`~pipeline.association.support.Outcome`).
    doubtful : dict name -> str
        Named landmarks whose predictions since their naming were too rarely seen, or whose
        bearings in the map scatter too widely
        (:meth:`~pipeline.association.support.Support.doubt`), with why; also in
        ``unresolved`` (key ``"<name> doubtful"``).
    unconfirmed : dict name -> str
        Named landmarks, not doubtful, seen at too few keyframes since their naming to confirm
        the name (:meth:`~pipeline.association.support.Support.unconfirmed`), with why; names
        given with this movement included.
    retracted : dict name -> str
        Doubtful names taken back with this movement and given to a landmark a full catalog
        kept out, or once the log is processed names under suspicion given anew (in
        ``confirmed`` too; the estimator must forget the old landmark before it takes
        ``history``); also in ``unresolved`` (key ``"<name> retracted"``).
    named_at_end : dict name -> str
        Once the log is processed (:func:`pipeline.association.final.repair_final`): free
        names given to landmarks the final map's unexplained detections point at (in
        ``confirmed`` too), with why.
    n_hypotheses : int
        Live hypotheses after this movement.
    pose : MovementPose or None
        The placement used (None: the movement could not be placed).
    assignment : MovementAssignment
        The movement's detections and their assignment: what the hypothesis step takes
        (no detections once the log is processed).
    """

    index: int
    bearings_o1_rad: dict[str, float] = field(default_factory=dict)
    bearings_o2_rad: dict[str, float] = field(default_factory=dict)
    names: dict[str, tuple[list[str | None], list[str | None]]] = field(default_factory=dict)
    confirmed: list[str] = field(default_factory=list)
    history: dict[str, list[tuple[int, int, float]]] = field(default_factory=dict)
    unresolved: dict[str, str] = field(default_factory=dict)
    not_visible: dict[str, str] = field(default_factory=dict)
    outcomes: dict[str, list[Outcome]] = field(default_factory=dict)
    doubtful: dict[str, str] = field(default_factory=dict)
    unconfirmed: dict[str, str] = field(default_factory=dict)
    retracted: dict[str, str] = field(default_factory=dict)
    named_at_end: dict[str, str] = field(default_factory=dict)
    n_hypotheses: int = 0
    pose: MovementPose | None = None
    assignment: MovementAssignment = field(kw_only=True)

    def report(self) -> None:
        """Every detection of :attr:`assignment` unnamed, then per class and keyframe assigned
        the names and bearings given, and what became of each prediction (too uncertain,
        outside the view, seen, missed, hidden, contested)."""
        record = self.assignment
        for label, (d1, d2) in record.detections_rad.items():
            self.names[label] = ([None] * d1.size, [None] * d2.size)
            if label not in record.predicted:
                continue
            for end, where in ((0, "O1"), (1, "O2")):
                self._report_at(
                    label,
                    end,
                    where,
                    record.predicted[label][end],
                    record.decided[label][end],
                    record.detections_rad[label][end],
                )

    def _report_at(
        self,
        label: str,
        end: int,
        where: str,
        p: Predicted,
        a: Assignment,
        det: NDArray[np.float64],
    ) -> None:
        for name, std in p.vague:
            self.unresolved[f"{name}@{where}"] = (
                f"predicted bearing too uncertain to associate (std {deg_text(std)})"
            )
            self.outcomes.setdefault(name, []).append("vague")
        for name, pred in p.away:
            self.not_visible[f"{name}@{where}"] = (
                f"predicted at {deg_text(pred)}, outside the camera's field of view"
            )
        usable = p.names
        bmap = self.bearings_o1_rad if end == 0 else self.bearings_o2_rad
        for i, j in a.pairs:
            bmap[usable[i]] = float(det[j])
            self.names[label][end][j] = usable[i]
            self.outcomes.setdefault(usable[i], []).append("seen")
        for i in a.missing:
            self.not_visible[f"{usable[i]}@{where}"] = (
                f"predicted at {deg_text(float(p.bearing_rad[i]))}, not detected (hidden or "
                "out of range)"
            )
            self.outcomes.setdefault(usable[i], []).append("missed")
        for i, front in a.hidden:
            self.not_visible[f"{usable[i]}@{where}"] = (
                f"predicted at {deg_text(float(p.bearing_rad[i]))}, hidden behind {usable[front]}"
            )
            self.outcomes.setdefault(usable[i], []).append("hidden")
        for i in a.contested_landmarks:
            self.outcomes.setdefault(usable[i], []).append("contested")
        if a.contested_landmarks or a.contested_detections:
            self.unresolved[f"{label}@{where}"] = _contested_text(a, usable, det)


def _contested_text(a: Assignment, names: list[str], det: NDArray[np.float64]) -> str:
    lms = ", ".join(names[i] for i in a.contested_landmarks) or "no landmark"
    bs = ", ".join(deg_text(float(det[j])) for j in a.contested_detections) or "none"
    return (
        f"{lms}: several plausible detections or overlapping predictions (detections at {bs}); "
        "not used"
    )
