"""The Rerun sink: every stage of the method as Rerun entities on two timelines.

Timelines: ``log_time`` (when the recorder wrote the frame) and ``movement`` (movement index).
Entities (the blueprint in :mod:`replay.blueprint` lays them out):

=============================== ===================================================
``camera/panorama``             the frame (the logged PNG as is; raw frames as BGR pixels), with
                                ``/masks`` (segmentation, one class per landmark) and
                                ``/detections`` (a line per bearing, labelled) and
                                ``/rejected`` (a line per blob rejected, labelled with the
                                reason: a size no landmark can have, cut by the image's edge)
``bearings/<name>``             bearing in degrees over time
``fr/cones/<name>``             per movement, the two vision cones (FR: O1 = (0, 0), O2 = (1, 0))
``fr/particles/<name>``         per movement, the particles drawn in the cones' intersection
                                (joint estimator: until the landmark is in the map)
``fr/observation``              O1 and O2
``map/particles/<name>``        the belief in FL after each movement (joint: its initializer's,
                                until the landmark is in the map)
``map/estimates``               means (labelled); ``map/ellipses/<name>``: 80% credible regions
``map/reference``               L1 = (0, 0) and L2 = (1, 0)
``map/trajectory``              observation points O1 -> O2 of every movement so far, in FL
``map/truth/...``               simulated logs: true landmarks and trajectory, mapped to FL
``error/<name>``, ``error/mean`` distance of each estimate to the truth (m), simulated logs
``log``                         skipped movements and landmarks, with the reason; joint estimator:
                                each movement's placement and re-initializations
``residuals/rms_deg``           joint estimator: RMS of the movement's bearing residuals, and
``residuals/noise_deg``         the bearing noise estimated from all residuals (degrees)
``fig1/...``                    the paper's Fig. 1 for this log's eps (:mod:`replay.fig1`)
=============================== ===================================================

Temporal entities are gathered and sent as columns (:class:`replay.sinks.rerun_columns.
ColumnBuffer`) every :data:`BATCH_ROWS` frames and movements, at the end, and (a followed log)
with each movement.

Rerun's 2-D views draw y downwards; the ``fr`` and ``map`` roots carry a static y-flip so FR and
FL are drawn with y up while the logged values stay in their frame.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import rerun as rr
from numpy.typing import NDArray

from data_schemas.calibration import Calibration, PinholeCalibration, UnwrappedCalibration
from data_schemas.session import Session, shared_classes
from pipeline.bearings.pinhole import bearing_polyline
from replay.fig1 import log_fig1
from replay.records import (
    AssociationRecord,
    EstimateRecord,
    FrameRecord,
    MovementRecord,
    RunInfo,
)
from replay.sinks.palette import (
    ELLIPSE_RGB,
    REJECTED_RGB,
    TRAJECTORY_RGB,
    TRUTH_RGB,
    landmark_rgb,
)
from replay.sinks.rerun_columns import ColumnBuffer, Strips
from replay.truth import errors_m

Y_UP = rr.Transform3D(mat3x3=[[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]])
FR_APEXES = ((0.0, 0.0), (1.0, 0.0))
#: frames and movements gathered before their entities are sent (as columns) to the recording
BATCH_ROWS = 64


def shorten(
    polygon: NDArray[np.float64], apex: tuple[float, float], reach: float
) -> NDArray[np.float64]:
    """A closed copy of ``polygon`` (k, 2) with vertices pulled within ``reach`` of ``apex``.

    Vision cones run to R_max (far beyond the landmarks); for display they are cut at ``reach``.
    """
    d = polygon - apex
    r = np.hypot(d[:, 0], d[:, 1])
    scale = np.minimum(1.0, reach / np.maximum(r, 1e-12))
    out = apex + d * scale[:, None]
    return np.vstack([out, out[:1]])


def class_labels(masks: Mapping[str, NDArray[np.bool_]], names: Sequence[str]) -> NDArray[np.uint8]:
    """One (H, W) class image from each landmark's (H, W) mask: ``k + 1`` where ``names[k]``'s
    mask is set (where masks overlap, the later name's), 0 elsewhere (at most 255 names)."""
    labels = np.zeros(next(iter(masks.values())).shape, np.uint8)
    for i, name in enumerate(names, start=1):
        mask = masks.get(name)
        if mask is not None:
            np.maximum(labels, mask.view(np.uint8) * np.uint8(i), out=labels)
    return labels


def detection_strips(calibration: Calibration, bearings_rad: Sequence[float]) -> Strips:
    """Image lines (pixels, x right, y down) that mark each bearing on the frame: a column of
    the unwrapped panorama, a ray of the omni image, a polyline bent by the lens (pinhole; no
    point for a bearing behind the camera)."""
    if isinstance(calibration, PinholeCalibration):
        lines = [bearing_polyline(calibration, b) for b in bearings_rad]
        return Strips.of([np.zeros((0, 2)) if line is None else line for line in lines])
    b = np.repeat(np.asarray(bearings_rad, np.float64), 2)  # each line's two ends
    if isinstance(calibration, UnwrappedCalibration):
        x = calibration.column_of_bearing(b)
        y = np.tile([0.0, float(calibration.height)], len(bearings_rad))
    else:
        x, y = calibration.pixel_of_bearing(b, np.tile([0.0, calibration.r_max], len(bearings_rad)))
    return Strips(np.stack([x, y], axis=1), np.full(len(bearings_rad), 2, np.int64))


class RerunSink:
    """Streams one log's stage results to a :class:`rerun.RecordingStream`.

    Parameters
    ----------
    rec : rerun.RecordingStream
        Where to log (its sink: file, viewer, server, is the caller's choice).
    images : bool
        Log every frame (with masks); False logs only the keyframes (panorama, masks, bearings:
        smaller, faster).
    live : bool
        Send what is gathered with each movement (a followed log), not only in batches of
        ``BATCH_ROWS`` frames and movements.
    """

    def __init__(self, rec: rr.RecordingStream, *, images: bool = True, live: bool = False) -> None:
        self.rec = rec
        self._live = live
        self.wants_images = True  # the keyframes' panoramas are shown either way
        self.wants_all_frames = images
        self._run: RunInfo | None = None
        self._rgb: dict[str, tuple[int, int, int]] = {}
        self._trajectory_fl = np.zeros((0, 2, 2))
        self._trajectory_labels: list[str] = []
        self._doubtful: dict[str, str] = {}
        self._unconfirmed: dict[str, str] = {}
        self._last_movement: int | None = None
        self._truth_trajectory_fl = np.zeros((0, 2, 2))
        self._buffer = ColumnBuffer()
        self._gathered = 0  # frames and movements in the buffer
        self._time: tuple[int, int | None] = (0, None)  # log time (ns), movement of the rows

    # ------------------------------------------------------------------ start
    def start(self, run: RunInfo) -> None:
        self._run = run
        s = run.session
        self._rgb = landmark_rgb(s)
        log_fig1(self.rec, s.vision_error_rad)
        log = self.rec.log
        log("log", rr.TextLog(f"map made by the {run.estimator} estimator", level="INFO"))
        log("fr", Y_UP, static=True)
        log("map", Y_UP, static=True)
        classes = [rr.ClassDescription(info=(0, "background", (0, 0, 0)))]
        for i, name in enumerate(s.landmark_names(), start=1):
            classes.append(rr.ClassDescription(info=(i, name, self._rgb[name])))
        log("camera/panorama", rr.AnnotationContext(classes), static=True)
        if s.calibration is not None:
            mask_format = rr.components.ImageFormat(
                width=s.calibration.width, height=s.calibration.height, channel_datatype="U8"
            )
            masks = rr.SegmentationImage.from_fields(format=mask_format, opacity=0.5)
            log("camera/panorama/masks", masks, static=True)
        lines = rr.LineStrips2D.from_fields(radii=rr.Radius.ui_points(1.5))
        log("camera/panorama/detections", lines, static=True)
        gone = rr.LineStrips2D.from_fields(radii=rr.Radius.ui_points(1.0), colors=[REJECTED_RGB])
        log("camera/panorama/rejected", gone, static=True)
        for name in self._rgb:  # the catalog, then names given by association (red#1, ...)
            series = rr.SeriesPoints(colors=[self._rgb[name]], names=[name], marker_sizes=[2.0])
            log(f"bearings/{name}", series, static=True)
            line = rr.SeriesLines(colors=[self._rgb[name]], names=[name])
            log(f"error/{name}", line, static=True)
        log("error/mean", rr.SeriesLines(colors=[(255, 255, 255)], names=["mean"]), static=True)
        ref = s.reference
        log(
            "map/reference",
            rr.Points2D(
                [[0.0, 0.0], [1.0, 0.0]],
                radii=0.02,
                colors=[self._rgb[ref[0]], self._rgb[ref[1]]],
                labels=list(ref),
            ),
            static=True,
        )
        log(
            "fr/observation",
            rr.Points2D([[0.0, 0.0], [1.0, 0.0]], radii=0.04, labels=["O1", "O2"]),
            static=True,
        )
        if run.truth is not None:
            truth_fl = run.truth.landmarks_fl()
            names = list(truth_fl)
            log(
                "map/truth/landmarks",
                rr.Points2D(
                    np.array([truth_fl[n] for n in names]),
                    radii=0.012,
                    colors=[TRUTH_RGB],
                    labels=[f"{n} (true)" for n in names],
                    show_labels=False,
                ),
                static=True,
            )

    def _add(self, entity: str, archetype: type[rr.AsComponents], **fields: Any) -> None:
        """One row of ``archetype`` on ``entity`` at the current row time, to be sent."""
        self._buffer.add(entity, *self._time, archetype, **fields)

    def _send(self) -> None:
        """Send the gathered rows as columns."""
        self._buffer.send(self.rec)
        self._gathered = 0

    def _gather(self) -> None:
        """Count one frame or movement in the buffer; send it when it is full."""
        self._gathered += 1
        if self._gathered >= BATCH_ROWS:
            self._send()

    # ------------------------------------------------------------------ frames
    def frame(self, frame: FrameRecord) -> None:
        assert self._run is not None
        movement = frame.keyframe[0] if frame.keyframe else None
        self._time = (frame.log_time_ns, movement)
        add = self._add
        if frame.png is not None:  # the logged PNG as is: no decoding, no raw pixels to copy
            add("camera/panorama", rr.EncodedImage, blob=[frame.png], media_type=["image/png"])
        elif frame.image_bgr is not None:  # raw pixels: sent at once, not held in a batch
            height, width = frame.image_bgr.shape[:2]
            pixels = rr.components.ImageFormat(
                width=width, height=height, color_model="BGR", channel_datatype="U8"
            )
            raw = ColumnBuffer()
            raw.add(
                "camera/panorama",
                *self._time,
                rr.Image,
                buffer=[np.ascontiguousarray(frame.image_bgr).ravel()],
                format=[pixels],
            )
            raw.send(self.rec)
        if frame.masks is not None:
            labels = class_labels(frame.masks, self._run.session.landmark_names())
            add("camera/panorama/masks", rr.SegmentationImage, buffer=[labels.ravel()])
        seen = {
            d.name: d.bearing_rad
            for d in frame.detections.values()
            if d.visible and d.bearing_rad is not None
        }
        cal = self._run.session.calibration
        if frame.image_bgr is not None and cal is not None:  # frames come with a camera only
            add(
                "camera/panorama/detections",
                rr.LineStrips2D,
                strips=detection_strips(cal, list(seen.values())),
                colors=[self._rgb[n] for n in seen],
                labels=[f"{n} {math.degrees(b):.1f}°" for n, b in seen.items()],
            )
            rejected = sorted(
                {(b.bearing_rad, why) for d in frame.detections.values() for b, why in d.rejected}
            )
            if rejected:
                add(
                    "camera/panorama/rejected",
                    rr.LineStrips2D,
                    strips=detection_strips(cal, [b for b, _ in rejected]),
                    labels=[f"rejected: {why}" for _, why in rejected],
                )
        for name, b in seen.items():
            add(f"bearings/{name}", rr.Scalars, scalars=[math.degrees(b)])
        self._gather()

    # ------------------------------------------------------------------ movements
    def movement(self, record: MovementRecord) -> None:
        assert self._run is not None
        run = self._run
        self._time = (record.log_time_ns, record.index)
        self._last_movement = record.index
        if not record.ok:
            self._text(f"movement {record.index}: {record.status}", "WARN")
        else:
            for name, reason in record.skipped_landmarks.items():
                self._text(f"movement {record.index}: {name} skipped: {reason}", "INFO")
            self._log_joint(record)
            self._log_fr(record, run.session)
            self._log_fl(record, run)
        if self._live:
            self._send()
        else:
            self._gather()

    def association(self, record: AssociationRecord) -> None:
        # with the last movement on its timeline: sent after it, the final map wins there
        self._time = (record.log_time_ns, self._last_movement)
        self._text(record.text(), "INFO")
        for name, why in record.retracted.items():
            self._text(f"with the final map, {name} {why}", "WARN")
            self._doubtful.pop(name, None)
            self._unconfirmed.pop(name, None)
        for name, why in record.named_at_end.items():
            self._text(f"with the final map, {name} {why}", "INFO")
        if record.estimates is not None and self._run is not None:
            names = [n for n in record.estimates if n not in self._run.session.reference]
            self._log_map(record.estimates, names)
            self._log_errors(record.estimates, names, self._run)
        for label, text in record.reports.items():
            self._text(f"{label} with the final map: {text}", "WARN")
        self._send()

    def _text(self, text: str, level: str) -> None:
        self._add("log", rr.TextLog, text=[text], level=[level])

    def _log_joint(self, record: MovementRecord) -> None:
        """Placement, residuals, noise estimate and re-initialization (joint estimator only)."""
        if record.placement:
            self._text(f"movement {record.index}: placed by {record.placement}", "INFO")
        if record.divergence:
            self._text(f"movement {record.index}: map re-initialized: {record.divergence}", "WARN")
        if record.solved_again:
            why = record.solved_again
            self._text(f"movement {record.index}: map stuck ({why}), solved again", "WARN")
        res = [r for pair in record.residuals_rad.values() for r in pair if r is not None]
        if res:
            rms_deg = math.degrees(math.sqrt(np.mean(np.square(res))))
            self._add("residuals/rms_deg", rr.Scalars, scalars=[rms_deg])
        if record.bearing_noise_rad is not None:
            noise_deg = math.degrees(record.bearing_noise_rad)
            self._add("residuals/noise_deg", rr.Scalars, scalars=[noise_deg])

    def _log_fr(self, record: MovementRecord, session: Session) -> None:
        add = self._add
        for name in session.landmark_names():
            particles = record.particles_fr.get(name)
            cones = record.cones_fr.get(name)
            if cones is None:
                add(f"fr/cones/{name}", rr.Clear, is_recursive=[False])
            else:
                reach = 1.5 if particles is None else 1.5 * float(np.abs(particles).max()) + 0.5
                outlines = [
                    shorten(c, apex, reach) for c, apex in zip(cones, FR_APEXES, strict=True)
                ]
                add(
                    f"fr/cones/{name}",
                    rr.LineStrips2D,
                    strips=Strips.of(outlines),
                    colors=[self._rgb[name]],
                )
            if particles is None:
                add(f"fr/particles/{name}", rr.Clear, is_recursive=[False])
            else:
                add(
                    f"fr/particles/{name}",
                    rr.Points2D,
                    positions=particles,
                    colors=[self._rgb[name]],
                    radii=[rr.Radius.ui_points(2.0)],
                )

    def _log_fl(self, record: MovementRecord, run: RunInfo) -> None:
        add = self._add
        for name, particles in record.particles_fl.items():
            add(
                f"map/particles/{name}",
                rr.Points2D,
                positions=particles,
                colors=[self._rgb[name]],
                radii=[rr.Radius.ui_points(1.5)],
            )
        if run.estimator == "joint":
            # its initializer's belief stops with the landmark's entry in the map
            for name in record.estimates.keys() - record.particles_fl.keys():
                add(f"map/particles/{name}", rr.Clear, is_recursive=[False])
        names = [n for n in record.estimates if n not in run.session.reference]
        doubtful = record.doubtful_landmarks or {}
        self._doubtful = dict(doubtful)
        self._unconfirmed = dict(record.unconfirmed_landmarks or {})
        self._log_map(record.estimates, names)
        for name, why in doubtful.items():
            self._text(f"movement {record.index}: {name} doubtful: {why}", "WARN")
        for name, rays in record.named_from.items():
            moves = sorted({m for m, _, _ in rays})
            text = (
                f"movement {record.index}: {name} named from {len(rays)} detections "
                f"(movements {moves[0]}-{moves[-1]})"
            )
            self._text(text, "INFO")
        if record.rays_fl:
            measured = list(record.rays_fl)
            add(
                "map/rays",
                rr.LineStrips2D,
                strips=Strips.of([record.rays_fl[n] for n in measured]),
                colors=[self._rgb[n] for n in measured],
                radii=[rr.Radius.ui_points(0.75)],
                labels=measured,
            )
        if record.o1_fl is not None and record.o2_fl is not None:
            add(
                "map/observation_particles",
                rr.Points2D,
                positions=np.vstack([record.o1_fl, record.o2_fl]),
                colors=[TRAJECTORY_RGB],
                radii=[rr.Radius.ui_points(1.0)],
            )
            ends = np.array([[record.o1_fl.mean(0), record.o2_fl.mean(0)]])
            self._trajectory_fl = np.concatenate([self._trajectory_fl, ends])
            k = len(self._trajectory_fl) - 1
            self._trajectory_labels += [f"O{k}.1", f"O{k}.2"]
            self._log_path(
                "map/trajectory", self._trajectory_fl, TRAJECTORY_RGB, self._trajectory_labels
            )
        truth = run.truth
        if truth is None:
            return
        if record.truth_o1_world is not None and record.truth_o2_world is not None:
            ends = truth.to_fl.apply(np.array([record.truth_o1_world, record.truth_o2_world]))
            self._truth_trajectory_fl = np.concatenate([self._truth_trajectory_fl, ends[None]])
            self._log_path("map/truth/trajectory", self._truth_trajectory_fl, TRUTH_RGB, None)
        self._log_errors(record.estimates, names, run)

    def _log_map(self, estimates: Mapping[str, EstimateRecord], names: Sequence[str]) -> None:
        """The map's points (labelled, doubtful and unconfirmed names marked) and 80% ellipses."""
        status = {
            **{n: " (unconfirmed)" for n in self._unconfirmed},
            **{n: " (doubtful)" for n in self._doubtful},
        }
        if names:
            self._add(
                "map/estimates",
                rr.Points2D,
                positions=np.array([estimates[n].mean_fl for n in names]),
                colors=[self._rgb[n] for n in names],
                radii=[rr.Radius.ui_points(5.0)],
                labels=[n + status.get(n, "") for n in names],
            )
        for n in names:
            self._add(
                f"map/ellipses/{n}",
                # its own hue and thicker than the particles, so the region shows over its own cloud
                rr.LineStrips2D,
                strips=Strips.of([estimates[n].ellipse80_fl]),
                colors=[ELLIPSE_RGB],
                radii=[rr.Radius.ui_points(1.5)],
                labels=[f"{n} 80%"],
            )

    def _log_errors(
        self, estimates: Mapping[str, EstimateRecord], names: Sequence[str], run: RunInfo
    ) -> None:
        """Simulated logs: each landmark's error and their mean (m)."""
        if run.truth is None:
            return
        means = {n: estimates[n].mean_fl for n in names}
        errors = errors_m(run.truth, means, shared_classes(run.session.landmarks))
        for n, e in errors.items():
            self._add(f"error/{n}", rr.Scalars, scalars=[e])
        if errors:
            self._add("error/mean", rr.Scalars, scalars=[float(np.mean(list(errors.values())))])

    def _log_path(
        self,
        entity: str,
        segments: NDArray[np.float64],
        rgb: tuple[int, int, int],
        labels: list[str] | None,
    ) -> None:
        """A path so far: its segments (k, 2, 2) as strips, their ends as points (labelled)."""
        self._add(
            entity,
            rr.LineStrips2D,
            strips=Strips.of(segments),
            colors=[rgb],
            radii=[rr.Radius.ui_points(1.0)],
        )
        named = {} if labels is None else {"labels": list(labels)}
        self._add(
            entity,
            rr.Points2D,
            positions=segments.reshape(-1, 2),
            colors=[rgb],
            radii=[rr.Radius.ui_points(3.0)],
            **named,
        )

    def finish(self) -> None:
        """Send the rows still gathered; the caller flushes or disconnects the stream."""
        if self._run is not None and len(self._buffer):
            self._send()
