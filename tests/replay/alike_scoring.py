"""Scoring association on simulated logs: which true landmark each associated bearing saw.

A bearing given to ``blue#k`` at a keyframe (then, or later with the name: ``named_from``) is
correct when it is within the bearing error bound eps of the true bearing (from the true
keyframe; heading: the movement's true direction) of the true landmark
:func:`replay.truth.match_truth` matches ``blue#k`` to: a blob where two landmarks line up is a
correct bearing of either. ``n_nearest`` counts the stricter reading:
that landmark is also the one of the class whose true bearing is nearest.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from data_schemas.angles import wrap_rad
from data_schemas.session import shared_classes
from replay.records import (
    AssociationRecord,
    FrameRecord,
    MethodConfig,
    MovementRecord,
    RunInfo,
)
from replay.sinks.summary import RunSummary, SummarySink
from replay.stages import run_log
from replay.truth import match_truth


@dataclass
class Collect:
    """A sink keeping the movement records."""

    wants_all_frames: bool = False
    wants_images: bool = False
    run: RunInfo | None = None
    records: list[MovementRecord] = field(default_factory=list)
    frames: list[FrameRecord] = field(default_factory=list)
    final: AssociationRecord | None = None

    def start(self, run: RunInfo) -> None:
        self.run = run

    def frame(self, frame: FrameRecord) -> None:
        if frame.keyframe is not None:
            self.frames.append(frame)

    def movement(self, record: MovementRecord) -> None:
        self.records.append(record)

    def association(self, record: AssociationRecord) -> None:
        self.final = record

    def finish(self) -> None:
        pass


@dataclass(frozen=True)
class Score:
    """Association and map figures of one run.

    ``n_final_detections``, ``n_final_named``, ``n_final_correct``, ``n_final_nearest``: the
    keyframe detections associated again with the final map once the log is processed (every
    one; those associated: named, or one blob where named landmarks line up; those associated
    right; those associated with the nearest in bearing).
    ``errors_m`` is measured on the final map (after names retracted once the log was
    processed), ``errors_last_m`` on the last movement's. ``result``: the run's summary, as the
    result line reads it.
    """

    n_correct: int
    n_nearest: int
    n_associated: int
    n_detections: int
    n_named: int
    n_true: int
    errors_m: dict[str, float]
    matched: dict[str, str]
    summary: dict[str, Any]
    n_final_detections: int
    n_final_named: int
    n_final_correct: int
    n_final_nearest: int
    errors_last_m: dict[str, float]
    result: RunSummary

    @property
    def correct_share(self) -> float:
        """Correct among the detections given a name."""
        return self.n_correct / max(self.n_associated, 1)

    @property
    def wrong_share(self) -> float:
        """Wrongly named among every keyframe detection of the class (the rest: correctly
        named, or left unnamed and reported)."""
        return (self.n_associated - self.n_correct) / max(self.n_detections, 1)


def score_log(log: Path, method: MethodConfig | None = None) -> Score:
    """Process ``log`` and score its association against the simulator's truth."""
    collect, summary = Collect(), SummarySink()
    run_log(log, method or MethodConfig(), [collect, summary])
    assert collect.run is not None and collect.run.truth is not None
    truth, session = collect.run.truth, collect.run.session
    classes = shared_classes(session.landmarks)
    last = next(r for r in reversed(collect.records) if r.ok)
    final_map = collect.final.estimates if collect.final is not None else None
    estimates = last.estimates if final_map is None else final_map  # the map once processed
    means = {n: e.mean_fl for n, e in estimates.items() if "#" in n}
    matched = match_truth(truth, means, classes)
    members = {n: label for label, names in classes.items() for n in names}
    eps = session.vision_error_rad
    keyframes = {
        rec.index: (rec.truth_o1_world, rec.truth_o2_world)
        for rec in collect.records
        if rec.truth_o1_world is not None and rec.truth_o2_world is not None
    }
    # every bearing given to a name: at its keyframe, or later with the name (named_from)
    given = [
        (name, rec.index, end, b)
        for rec in collect.records
        for name, pair in rec.bearings_rad.items()
        for end, b in enumerate(pair)
        if b is not None
    ]
    given += [
        (name, movement, end, b)
        for rec in collect.records
        for name, rays in rec.named_from.items()
        for movement, end, b in rays
    ]

    def judge(name: str, movement: int, end: int, b: float) -> tuple[bool, bool]:
        """Whether the bearing ``b`` given to ``name`` is its matched landmark's (within eps),
        and whether that landmark is also the class's nearest in bearing."""
        o1, o2 = keyframes[movement]
        d = o2 - o1
        heading = math.atan2(d[1], d[0])
        label = name.rpartition("#")[0]
        trues = [n for n, c in members.items() if c == label]
        pts = np.array([truth.landmarks_world[n] for n in trues])
        v = pts - (o1, o2)[end]
        err = np.abs(wrap_rad(np.arctan2(v[:, 1], v[:, 0]) - heading - b))
        own = matched.get(name)
        right = own is not None and bool(err[trues.index(own)] <= eps)
        return right, trues[int(np.argmin(err))] == own

    correct = nearest = associated = 0
    for name, movement, end, b in given:
        if "#" not in name or movement not in keyframes:
            continue
        right, near = judge(name, movement, end, b)
        associated += 1
        correct += right
        nearest += near
    final = collect.final.detections if collect.final is not None else []
    # associated: named, or one blob where landmarks line up (right when one of them is its
    # matched landmark within eps, as a blob of two landmarks lined up is a bearing of either)
    final_named = [
        ((d.name,) if d.name is not None else d.in_line, d)
        for d in final
        if (d.name is not None or d.in_line) and d.movement in keyframes
    ]
    final_judged = [
        [judge(n, d.movement, d.end, d.bearing_rad) for n in names] for names, d in final_named
    ]
    final_correct = sum(any(right for right, _ in js) for js in final_judged)
    final_nearest = sum(any(near for _, near in js) for js in final_judged)
    errors = {n: truth.error_m(t, means[n]) for n, t in matched.items()}
    last_means = {n: e.mean_fl for n, e in last.estimates.items() if "#" in n}
    errors_last = {
        n: truth.error_m(t, last_means[n])
        for n, t in match_truth(truth, last_means, classes).items()
    }
    firsts = [names[0] for names in classes.values()]
    detections = sum(len(f.detections[n].blobs) for f in collect.frames for n in firsts)
    return Score(
        correct,
        nearest,
        associated,
        detections,
        len(means),
        sum(len(v) for v in classes.values()),
        errors,
        matched,
        summary.document,
        len(final),
        len(final_named),
        final_correct,
        final_nearest,
        errors_last,
        summary.summary,
    )
