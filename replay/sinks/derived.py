"""The derived-log sink: the stages' outputs as MCAP channels (logs in, logs out).

Written with the recorder's crash-safe :class:`~data_schemas.mcap.writer.LogWriter`: the session
metadata of the source log comes first (with a ``derived`` block naming the source and the
method), then ``/pipeline/bearings`` per processed frame and ``/pipeline/particles_fr``,
``/pipeline/particles_fl``, ``/pipeline/estimate`` per movement, each at the ``log_time`` of the
source frame it comes from, so source and derived logs line up in time; with landmarks that look
alike, ``/pipeline/association`` at the end (every keyframe detection with the final map).

Beside them, the same results in Foxglove's well-known schemas (:mod:`.foxglove`), so that its 3D
panel shows the map: ``/pipeline/map`` (``foxglove.SceneUpdate``, after each movement and for the
final map), ``/pipeline/keyframe_poses`` and ``/pipeline/trajectory``
(``foxglove.PosesInFrame``), ``/pipeline/tf`` (``foxglove.FrameTransform`` ``fl`` -> ``robot``)
and ``/pipeline/particles`` (``foxglove.PointCloud``).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import fields
from functools import cache
from typing import Any

import numpy as np
from numpy.typing import NDArray

from data_schemas.mcap.writer import LogWriter, SettableClock
from data_schemas.registry import schema_dict
from data_schemas.stamps import Stamp, stamp_from_ns
from pipeline.bearings.detection import Detection
from replay.records import (
    AssociationRecord,
    EstimateRecord,
    FrameRecord,
    MovementRecord,
    RunInfo,
)
from replay.sinks import foxglove
from replay.sinks.palette import ELLIPSE_RGB, landmark_rgb


def _cov_xy(cov: NDArray[np.floating]) -> dict[str, float]:
    """A 2x2 covariance as ``{xx, xy, yy}`` (Foxglove reads no arrays of arrays)."""
    return {"xx": float(cov[0, 0]), "xy": float(cov[0, 1]), "yy": float(cov[1, 1])}


def _landmark_rows(estimates: Mapping[str, EstimateRecord]) -> list[dict[str, Any]]:
    """A map's landmarks as ``/pipeline/estimate`` carries them: name, mean, covariance (FL)."""
    return [
        {"name": n, "mean": e.mean_fl.tolist(), "cov": _cov_xy(e.cov_fl)}
        for n, e in estimates.items()
    ]


def point_set(name: str, points: NDArray[np.floating]) -> dict[str, Any]:
    """A ``bslam.PointSet``: named particles (n, 2) as ``x`` and ``y`` lists."""
    p = np.asarray(points, np.float64).reshape(-1, 2)
    return {"name": name, "x": p[:, 0].tolist(), "y": p[:, 1].tolist()}


def _point_sets(sets: Mapping[str, NDArray[np.float64]]) -> list[dict[str, Any]]:
    return [point_set(name, p) for name, p in sets.items()]


@cache
def logged_detection_fields() -> tuple[str, ...]:
    """The :class:`~pipeline.bearings.detection.Detection` fields a ``bslam.Detection`` carries.

    The schema chooses: every dataclass field it declares, in the dataclass's order (the
    extractor's working fields, e.g. ``blobs``, stay out of the log).
    """
    declared = schema_dict("bslam.Detection")["properties"]
    return tuple(f.name for f in fields(Detection) if f.name in declared)


def detection_message(detection: Detection) -> dict[str, Any]:
    """A ``bslam.Detection`` from a :class:`~pipeline.bearings.detection.Detection`.

    Fields that are None (no bearing) are left out rather than null (Foxglove's schema parser
    has no nulls).
    """
    values = ((name, getattr(detection, name)) for name in logged_detection_fields())
    return {name: value for name, value in values if value is not None}


def _joint_fields(record: MovementRecord) -> dict[str, Any]:
    """The joint estimator's additions to ``/pipeline/estimate`` (absent ends left out)."""
    out: dict[str, Any] = {}
    if record.placement:
        out["placement"] = str(record.placement)
    if record.bearing_noise_rad is not None:
        out["bearing_noise_rad"] = record.bearing_noise_rad
    if record.divergence:
        out["divergence"] = record.divergence
    if record.solved_again:
        out["solved_again"] = record.solved_again
    if record.also_placed:
        out["also_placed"] = list(record.also_placed)
    if record.residuals_rad:
        rows = []
        for name, (r1, r2) in record.residuals_rad.items():
            row: dict[str, Any] = {"name": name}
            if r1 is not None:
                row["o1_rad"] = r1
            if r2 is not None:
                row["o2_rad"] = r2
            rows.append(row)
        out["residuals"] = rows
    return out


class DerivedLogSink:
    """Writes the derived log of one run to ``path``."""

    wants_all_frames = False
    wants_images = False

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = path
        self._clock = SettableClock()
        self._writer: LogWriter | None = None
        self._run: RunInfo | None = None
        self._rgb: dict[str, tuple[int, int, int]] = {}
        self._trajectory: list[foxglove.Pose2] = []

    def start(self, run: RunInfo) -> None:
        self._run = run
        self._rgb = landmark_rgb(run.session)
        doc = dict(run.session.doc)
        doc["derived"] = {
            "source": run.log_name,
            "method": run.method.summary(run.session.vision_error_rad),
        }
        self._writer = LogWriter(self.path, doc, clock=self._clock, fsync=False)

    def _write(self, log_time_ns: int, topic: str, msg: dict[str, Any]) -> None:
        assert self._writer is not None
        self._clock.t_ns = log_time_ns
        self._writer.write(topic, msg)

    def frame(self, frame: FrameRecord) -> None:
        detections = [detection_message(d) for d in frame.detections.values()]
        msg: dict[str, Any] = {
            "timestamp": stamp_from_ns(frame.timestamp_ns),
            "detections": detections,
        }
        if frame.keyframe is not None:
            msg["keyframe"] = {"index": frame.keyframe[0], "phase": frame.keyframe[1]}
        self._write(frame.log_time_ns, "/pipeline/bearings", msg)

    def movement(self, record: MovementRecord) -> None:
        assert self._run is not None
        stamp = stamp_from_ns(record.timestamp_ns)
        t = record.log_time_ns
        if record.ok:
            cones = [
                {"name": n, "bearing_o1_rad": b1, "bearing_o2_rad": b2}
                for n, (b1, b2) in record.bearings_rad.items()
                if n in record.particles_fr and b1 is not None and b2 is not None
            ]
            fr = {
                "timestamp": stamp,
                "index": record.index,
                "vision_error_rad": self._run.session.vision_error_rad,
                "cones": cones,
                "landmarks": _point_sets(record.particles_fr),
            }
            self._write(t, "/pipeline/particles_fr", fr)
            observation = {}
            if record.o1_fl is not None and record.o2_fl is not None:
                observation = {"O1": record.o1_fl, "O2": record.o2_fl}
            fl = {
                "timestamp": stamp,
                "index": record.index,
                "landmarks": _point_sets(record.particles_fl),
                "observation_points": _point_sets(observation),
            }
            self._write(t, "/pipeline/particles_fl", fl)
        estimate: dict[str, Any] = {
            "timestamp": stamp,
            "index": record.index,
            "status": str(record.status),
            "estimator": self._run.estimator,
            "skipped_landmarks": [
                {"name": n, "reason": r} for n, r in record.skipped_landmarks.items()
            ],
            "landmarks": _landmark_rows(record.estimates),
        }
        estimate.update(_joint_fields(record))
        if record.ok and record.o1_fl is not None and record.o2_fl is not None:
            estimate["observation_points"] = {
                "o1": record.o1_fl.mean(axis=0).tolist(),
                "o2": record.o2_fl.mean(axis=0).tolist(),
            }
        self._write(t, "/pipeline/estimate", estimate)
        self._foxglove_movement(record)

    def _foxglove_movement(self, record: MovementRecord) -> None:
        """One movement's results in Foxglove's schemas (:mod:`.foxglove`)."""
        stamp = stamp_from_ns(record.timestamp_ns)
        t = record.log_time_ns
        if record.ok and record.o1_fl is not None and record.o2_fl is not None:
            poses = foxglove.keyframe_poses(record.o1_fl, record.o2_fl)
            self._trajectory += poses
            self._write(t, "/pipeline/keyframe_poses", foxglove.poses_in_frame(stamp, poses))
            self._write(t, "/pipeline/trajectory", foxglove.poses_in_frame(stamp, self._trajectory))
            self._write(t, "/pipeline/tf", foxglove.robot_transform(stamp, poses[1]))
        if record.particles_fl:
            self._write(t, "/pipeline/particles", foxglove.point_cloud(stamp, record.particles_fl))
        if record.estimates:
            self._write_map(t, stamp, record.estimates)

    def _write_map(
        self, log_time_ns: int, stamp: Stamp, estimates: Mapping[str, EstimateRecord]
    ) -> None:
        msg = foxglove.scene_update(stamp, estimates, self._rgb, ELLIPSE_RGB)
        self._write(log_time_ns, "/pipeline/map", msg)

    def association(self, record: AssociationRecord) -> None:
        rows = []
        for d in record.detections:
            row: dict[str, Any] = {
                "movement": d.movement,
                "phase": ("start", "end")[d.end],
                "class": d.label,
                "bearing_rad": d.bearing_rad,
                "status": str(d.status),
            }
            if d.name is not None:
                row["name"] = d.name
            if d.in_line:
                row["in_line"] = list(d.in_line)
            rows.append(row)
        msg: dict[str, Any] = {"timestamp": stamp_from_ns(record.timestamp_ns), "detections": rows}
        if record.reports:
            msg["warnings"] = [{"class": c, "text": t} for c, t in record.reports.items()]
        if record.retracted:
            msg["retracted"] = [{"name": n, "text": t} for n, t in record.retracted.items()]
        if record.estimates is not None:
            msg["landmarks"] = _landmark_rows(record.estimates)
        if record.named_at_end:
            msg["named_at_end"] = [{"name": n, "text": t} for n, t in record.named_at_end.items()]
        if record.placed_by_matching:
            msg["placed_by_matching"] = list(record.placed_by_matching)
        self._write(record.log_time_ns, "/pipeline/association", msg)
        if record.estimates is not None:
            self._write_map(record.log_time_ns, msg["timestamp"], record.estimates)

    def finish(self) -> None:
        if self._writer is not None:
            self._writer.finish()
