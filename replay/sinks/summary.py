"""The summary sink: one JSON document per log, in the contract of ``docs/replay.md``.

``frame`` names the reference pair, ``method`` the settings, ``movements[k]`` the keyframe
bearings used (degrees, [-180, 180)) and the belief after movement k, ``landmarks`` the final
map (FL, unit |L1 L2|; the reference pair is the frame, so it is not listed). For simulated logs
``truth`` gives the true positions in FL and ``error_m`` the distance of each estimate to them.
With the joint estimator a movement also carries its ``placement`` (``reference pair`` or
``resection``), its bearing ``residuals_deg`` and the ``bearing_noise_deg`` estimated so far (and
``divergence`` when the map was re-initialized, ``solved_again`` when it was found stuck and
solved again from its whole record); the document ends with the final ``bearing_noise_deg``
and the numbers of ``reinitializations`` and of maps ``solved_again``.
``ambiguous_classes`` (class -> landmarks) lists the classes several catalog landmarks share;
their landmarks are named by association (``red#1``, ... in order of confirmation,
:mod:`pipeline.association`). ``movements[k].ambiguous_landmarks`` (key -> reason) is what
movement k left unresolved (contested or unexplained detections, a movement not placed),
``not_visible`` the named landmarks predicted but not detected, ``named_landmarks`` those named
with it and ``named_from`` the keyframe detections each was named from,
``unconfirmed_landmarks`` the names not yet seen often enough since their naming to tell;
``association`` sums up the names per class, the catalog counts, the movements with
something unresolved, per class the blobs ``detections`` at keyframes and how many of them got a
name (at their keyframe or later, ``named_from``), the names still ``doubtful`` after the last
movement (name -> why: seen too rarely where predicted since named, or bearings that scatter too
widely), those still ``unconfirmed`` (name -> why), per class ``final_map``: the keyframe
detections associated again with the final map once the log is processed (``named``,
``contested``, ``unexplained``, ``not placed``, ``per_name``, a ``warning`` when the final
map leaves several of its detections unexplained, every name of the class given or not,
``retracted``: names taken back then and given to the landmark those detections point at,
``named_at_end``: free names given then to landmarks unexplained detections point at; the
map once the log is processed is the document's ``landmarks``; and ``weak``: names the final
association gives a detection at too few of the keyframes where the final map predicts them,
or whose detections there do not meet at one point, name -> why),
``placed_by_matching`` (movements the map left out or held misplaced, placed for that
association by matching their detections with the final map) and, for simulated logs,
``matched_truth`` (each ``red#k`` matched to the nearest true landmark of its class,
one-to-one; ``error_m`` is measured against it). ``trust`` says whether the map is
``trustworthy`` and, when not, the ``reasons`` (:mod:`replay.trust`); with ``--from``/``--to``
the document ends with the ``window`` processed.

The sink also gives the run's outcome as data, :class:`RunSummary` (what the result line
says), built from the same records as the document; :meth:`RunSummary.to_json` is the document.
It is plain data, so it comes back whole from worker processes and Dask.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad
from data_schemas.mcap.window import LogWindow
from data_schemas.session import shared_classes
from pipeline.association.final import Status
from pipeline.slam import Placement
from replay.records import (
    AssociationRecord,
    EstimateRecord,
    FrameRecord,
    MovementRecord,
    RunInfo,
)
from replay.trust import trust_entry, trust_reasons
from replay.truth import class_of_name, errors_m, match_truth

DIGITS = 9


@dataclass(frozen=True)
class FinalAssociation:
    """The keyframe detections of shared classes associated again with the final map.

    Attributes
    ----------
    detections, explained : int
        Those detections, and how many of them the final map names or finds in line.
    placed_by_matching : tuple of int
        Movements the map left out or held misplaced, placed for this association by matching.
    named_at_end, retracted : tuple of str
        Names given then: free ones, and ones taken back from another landmark.
    missing : tuple of str
        Classes whose detections the final map leaves unexplained (a landmark may be missing).
    """

    detections: int
    explained: int
    placed_by_matching: tuple[int, ...]
    named_at_end: tuple[str, ...]
    retracted: tuple[str, ...]
    missing: tuple[str, ...]


@dataclass(frozen=True)
class AssociationOutcome:
    """What association did with the landmarks that look alike (shared colour classes).

    Attributes
    ----------
    names_given : dict of str to int
        Per class, the names the final map holds (``red#k``).
    catalog_count : dict of str to int
        Per class, the landmarks the catalog has.
    detections, detections_named : int
        Blobs of those classes at keyframes, and how many of them got a name (then or later).
    movements_with_unresolved : tuple of int
        Movements that left something unresolved.
    doubtful, unconfirmed : tuple of str
        Names still doubtful, or not yet seen often enough to tell, after the last movement
        (sorted).
    final : FinalAssociation or None
        The association with the final map, if it ran.
    """

    names_given: dict[str, int]
    catalog_count: dict[str, int]
    detections: int
    detections_named: int
    movements_with_unresolved: tuple[int, ...]
    doubtful: tuple[str, ...]
    unconfirmed: tuple[str, ...]
    final: FinalAssociation | None


@dataclass(frozen=True)
class RunSummary:
    """One processed log: what the result line says, and the summary document.

    Attributes
    ----------
    movements : int
        Movements in the log (or its window).
    used : int
        Movements that updated the map.
    resected : int
        Of those, movements placed by resection (joint estimator).
    reference : tuple of str
        The reference pair (origin, x axis): the frame FL, not mapped.
    landmarks : int
        Landmarks mapped besides the reference pair.
    bearing_noise_deg : float or None
        Bearing noise estimated by the joint estimator, degrees.
    mean_error_m : float or None
        Mean distance of the estimates to the truth (simulated logs), metres.
    association : AssociationOutcome or None
        With landmarks that look alike.
    untrusted : tuple of str
        Why the map is not trustworthy (empty: it is).
    document : dict
        The summary document (``docs/replay.md``); read it with :meth:`to_json`.
    """

    movements: int
    used: int
    resected: int
    reference: tuple[str, str]
    landmarks: int
    bearing_noise_deg: float | None = None
    mean_error_m: float | None = None
    association: AssociationOutcome | None = None
    untrusted: tuple[str, ...] = ()
    document: dict[str, Any] = field(default_factory=dict, repr=False)

    def to_json(self) -> dict[str, Any]:
        """The summary document (JSON types only)."""
        return self.document


def _num(x: float) -> float:
    return round(float(x), DIGITS)


def _xy(p: NDArray[np.floating]) -> list[float]:
    return [_num(p[0]), _num(p[1])]


def _bearing_deg(b: float | None) -> float | None:
    return None if b is None else round(math.degrees(wrap_rad(b)), 6)


def _estimate(e: EstimateRecord) -> dict[str, Any]:
    c = e.cov_fl
    return {"mean": _xy(e.mean_fl), "cov": [_xy(c[0]), _xy(c[1])]}


def _method(run: RunInfo) -> dict[str, Any]:
    """The ``method`` block: the run's settings (a driving log's: the driving estimator's)."""
    doc = run.method.summary(run.session.vision_error_rad)
    if run.driving:
        from replay.driving import driving_summary

        doc = {
            k: v for k, v in doc.items() if k not in ("n_r", "n_l", "distance_prior")
        } | driving_summary(run.method)
        doc["estimator"] = "driving"
    return doc


class SummarySink:
    """Builds the summary: :attr:`summary` (or :attr:`document`) once the run is finished.

    Parameters
    ----------
    window : LogWindow, optional
        The part of the log processed (``--from`` / ``--to``), recorded in the document.
    """

    wants_all_frames = False
    wants_images = False

    def __init__(self, window: LogWindow | None = None) -> None:
        self.document: dict[str, Any] = {}
        self._window = window
        self._summary: RunSummary | None = None
        self._used = 0
        self._resected = 0
        self._unresolved: list[int] = []
        self._association: AssociationOutcome | None = None
        self._run: RunInfo | None = None
        self._landmarks: dict[str, Any] = {}
        self._errors_m: dict[str, float] = {}
        self._noise_rad: float | None = None
        self._unit_m: float | None = None
        self._reinitializations = 0
        self._solved_again = 0
        self._matched: dict[str, str] = {}
        self._doubtful: dict[str, str] = {}
        self._unconfirmed: dict[str, str] = {}
        self._final: AssociationRecord | None = None
        # per shared class: blobs detected at keyframes, and those given a name (then or later)
        self._blobs: dict[str, int] = {}
        self._named_blobs: dict[str, int] = {}

    def start(self, run: RunInfo) -> None:
        self._run = run
        s = run.session
        self.document = {
            "log": run.log_name,
            "frame": {"origin": s.reference[0], "x_axis": s.reference[1]},
            "method": _method(run),
            "camera_model": None if s.calibration is None else s.calibration.model,
            "simulated": s.simulated,
            "movements": [],
            "landmarks": {},
        }
        shared = shared_classes(s.landmarks)
        if shared:
            self.document["ambiguous_classes"] = shared
        if run.truth is not None:
            self.document["truth"] = {
                "unit_m": _num(run.truth.to_fl.unit_m),
                "landmarks": {k: _xy(v) for k, v in run.truth.landmarks_fl().items()},
            }

    def frame(self, frame: FrameRecord) -> None:
        """Keyframes count the blobs of each shared class (frames are not in the summary)."""
        if frame.keyframe is None or self._run is None:
            return
        for label, names in shared_classes(self._run.session.landmarks).items():
            detection = frame.detections.get(names[0])  # one detection carries the class's blobs
            if detection is not None:
                self._blobs[label] = self._blobs.get(label, 0) + len(detection.blobs)

    def movement(self, record: MovementRecord) -> None:
        assert self._run is not None
        entry: dict[str, Any] = {
            "index": record.index,
            "status": str(record.status),
            "bearings_deg": {
                name: [_bearing_deg(b1), _bearing_deg(b2)]
                for name, (b1, b2) in record.bearings_rad.items()
            },
        }
        self._used += record.ok
        self._resected += record.placement == Placement.RESECTION
        if record.skipped_landmarks:
            entry["skipped_landmarks"] = dict(record.skipped_landmarks)
        if record.placement:
            entry["placement"] = str(record.placement)
        if record.residuals_rad:
            entry["residuals_deg"] = {
                name: [_bearing_deg(r1), _bearing_deg(r2)]
                for name, (r1, r2) in record.residuals_rad.items()
            }
        if record.bearing_noise_rad is not None:
            self._noise_rad = record.bearing_noise_rad
            entry["bearing_noise_deg"] = round(math.degrees(record.bearing_noise_rad), 6)
        if record.map_unit_m is not None:
            self._unit_m = record.map_unit_m
            entry["map_unit_m"] = _num(record.map_unit_m)
        if record.also_placed:
            entry["also_placed"] = list(record.also_placed)
        if record.divergence:
            entry["divergence"] = record.divergence
            self._reinitializations += 1
        if record.solved_again:
            entry["solved_again"] = record.solved_again
            self._solved_again += 1
        if record.ambiguous_landmarks:
            entry["ambiguous_landmarks"] = dict(record.ambiguous_landmarks)
            self._unresolved.append(record.index)
        if record.not_visible:
            entry["not_visible"] = dict(record.not_visible)
        if record.named_landmarks:
            entry["named_landmarks"] = list(record.named_landmarks)
        given = [(n, sum(b is not None for b in pair)) for n, pair in record.bearings_rad.items()]
        given += [(n, len(rays)) for n, rays in record.named_from.items()]
        for name, count in given:
            label = class_of_name(name)
            if label is not None:
                self._named_blobs[label] = self._named_blobs.get(label, 0) + count
        if record.named_from:
            entry["named_from"] = {
                name: [
                    {
                        "movement": m,
                        "at": "O1" if end == 0 else "O2",
                        "bearing_deg": _bearing_deg(b),
                    }
                    for m, end, b in rays
                ]
                for name, rays in record.named_from.items()
            }
        if record.doubtful_landmarks is not None:
            self._doubtful = dict(record.doubtful_landmarks)
        if record.unconfirmed_landmarks is not None:
            self._unconfirmed = dict(record.unconfirmed_landmarks)
            if self._unconfirmed:
                entry["unconfirmed_landmarks"] = dict(self._unconfirmed)
        if record.ok:
            self._set_map(record.estimates)
            if record.o1_fl is not None and record.o2_fl is not None:
                entry["observation_points"] = {
                    "o1": _xy(record.o1_fl.mean(axis=0)),
                    "o2": _xy(record.o2_fl.mean(axis=0)),
                }
        entry["landmarks"] = self._landmarks
        if self._run.truth is not None and self._errors_m:
            entry["error_m"] = {k: _num(v) for k, v in self._errors_m.items()}
            entry["mean_error_m"] = _num(float(np.mean(list(self._errors_m.values()))))
        self.document["movements"].append(entry)

    def _set_map(self, estimates: Mapping[str, EstimateRecord]) -> None:
        """The map now: its landmarks and, for simulated logs, their errors."""
        assert self._run is not None
        reference = self._run.session.reference
        self._landmarks = {
            name: _estimate(e) for name, e in estimates.items() if name not in reference
        }
        if self._run.truth is not None:
            means = {n: e.mean_fl for n, e in estimates.items() if n not in reference}
            shared = shared_classes(self._run.session.landmarks)
            self._errors_m = errors_m(self._run.truth, means, shared)
            if shared:
                self._matched = match_truth(self._run.truth, means, shared)

    def association(self, record: AssociationRecord) -> None:
        self._final = record
        if record.estimates is not None:
            self._set_map(record.estimates)
        for name in record.retracted:
            self._doubtful.pop(name, None)
            self._unconfirmed.pop(name, None)

    def finish(self) -> None:
        self.document["landmarks"] = self._landmarks
        if self._run is not None:
            self._association_summary(self._run)
        if self._unit_m is not None:
            self.document["map_unit_m"] = _num(self._unit_m)
        noise_deg = mean_error_m = None
        if self._noise_rad is not None:
            noise_deg = round(math.degrees(self._noise_rad), 6)
            self.document["bearing_noise_deg"] = noise_deg
            self.document["reinitializations"] = self._reinitializations
            self.document["solved_again"] = self._solved_again
        if self._errors_m:
            mean_error_m = _num(float(np.mean(list(self._errors_m.values()))))
            self.document["error_m"] = {k: _num(v) for k, v in self._errors_m.items()}
            self.document["mean_error_m"] = mean_error_m
        reasons = trust_reasons(self.document)
        self.document["trust"] = trust_entry(reasons)
        if self._window:
            bounds = (("from", self._window.start), ("to", self._window.end))
            self.document["window"] = {k: str(b) for k, b in bounds if b is not None}
        reference = self.document["frame"]["origin"], self.document["frame"]["x_axis"]
        self._summary = RunSummary(
            movements=len(self.document["movements"]),
            used=self._used,
            resected=self._resected,
            reference=reference,
            landmarks=len(self._landmarks),
            bearing_noise_deg=noise_deg,
            mean_error_m=mean_error_m,
            association=self._association,
            untrusted=tuple(reasons),
            document=self.document,
        )

    @property
    def summary(self) -> RunSummary:
        """The run's summary (once :meth:`finish` has run).

        Raises
        ------
        RuntimeError
            The run has not finished.
        """
        if self._summary is None:
            raise RuntimeError("the summary is complete only once the run has finished")
        return self._summary

    def _association_summary(self, run: RunInfo) -> None:
        """Per shared class: the names given, how many movements left something unresolved."""
        shared = shared_classes(run.session.landmarks)
        if not shared:
            return
        named = {
            label: sorted(
                (n for n in self._landmarks if class_of_name(n) == label),
                key=lambda n: int(n.rpartition("#")[2]),
            )
            for label in shared
        }
        catalog_count = {label: len(v) for label, v in shared.items()}
        self.document["association"] = {
            "named": named,
            "catalog_count": catalog_count,
            "movements_with_unresolved": list(self._unresolved),
            "detections": {
                label: {
                    "at_keyframes": self._blobs.get(label, 0),
                    "named": self._named_blobs.get(label, 0),
                }
                for label in shared
            },
        }
        if self._final is not None:
            final: dict[str, dict[str, Any]] = {
                label: dict(c) for label, c in self._final.counts().items()
            }
            for d in self._final.detections:
                if d.name is not None:
                    per_name = final[d.label].setdefault("per_name", {})
                    per_name[d.name] = per_name.get(d.name, 0) + 1
            for label, text in self._final.reports.items():
                final[label]["warning"] = text
            for key, given in (
                ("retracted", self._final.retracted),
                ("named_at_end", self._final.named_at_end),
                ("weak", self._final.weak),
            ):
                for name, why in given.items():
                    shared_label = class_of_name(name)
                    if shared_label in final:
                        final[shared_label].setdefault(key, {})[name] = why
            self.document["association"]["final_map"] = final
            if self._final.placed_by_matching:
                placed = list(self._final.placed_by_matching)
                self.document["association"]["placed_by_matching"] = placed
        if self._doubtful:
            self.document["association"]["doubtful"] = dict(sorted(self._doubtful.items()))
        if self._unconfirmed:
            self.document["association"]["unconfirmed"] = dict(sorted(self._unconfirmed.items()))
        if self._matched:
            self.document["association"]["matched_truth"] = dict(sorted(self._matched.items()))
        self._association = AssociationOutcome(
            names_given={label: len(names) for label, names in named.items()},
            catalog_count=catalog_count,
            detections=sum(self._blobs.get(label, 0) for label in shared),
            detections_named=sum(self._named_blobs.get(label, 0) for label in shared),
            movements_with_unresolved=tuple(self._unresolved),
            doubtful=tuple(sorted(self._doubtful)),
            unconfirmed=tuple(sorted(self._unconfirmed)),
            final=None if self._final is None else _final_association(self._final),
        )


def _final_association(final: AssociationRecord) -> FinalAssociation:
    """The typed form of the final association, class by class in the order of
    :meth:`AssociationRecord.counts` (the order of the summary's ``final_map``)."""
    labels = list(final.counts())

    def given(names: Mapping[str, str]) -> tuple[str, ...]:
        return tuple(n for label in labels for n in names if class_of_name(n) == label)

    return FinalAssociation(
        detections=len(final.detections),
        explained=sum(d.status in (Status.NAMED, Status.IN_LINE) for d in final.detections),
        placed_by_matching=tuple(final.placed_by_matching),
        named_at_end=given(final.named_at_end),
        retracted=given(final.retracted),
        missing=tuple(label for label in labels if label in final.reports),
    )
