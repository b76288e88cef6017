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

Frame-level entities (panorama, masks, detections, bearings) are gathered and sent as columns
every :data:`BATCH_FRAMES` frames and at the end; the rest is logged as it comes.

Rerun's 2-D views draw y downwards; the ``fr`` and ``map`` roots carry a static y-flip so FR and
FL are drawn with y up while the logged values stay in their frame.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field

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
from replay.truth import errors_m

LOG_TIME = "log_time"
MOVEMENT = "movement"
Y_UP = rr.Transform3D(mat3x3=[[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]])
FR_APEXES = ((0.0, 0.0), (1.0, 0.0))
#: frames gathered before their entities are sent (as columns) to the recording
BATCH_FRAMES = 64


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


def detection_segments(
    calibration: Calibration, bearings_rad: Iterable[float]
) -> list[NDArray[np.float64]]:
    """Image segments (pixels, x right, y down) that mark each bearing on the frame (pinhole: a
    polyline bent by the lens; empty for a bearing behind the camera)."""
    segments = []
    for b in bearings_rad:
        if isinstance(calibration, PinholeCalibration):
            line = bearing_polyline(calibration, b)
            segments.append(np.zeros((0, 2)) if line is None else line)
        elif isinstance(calibration, UnwrappedCalibration):
            u = float(calibration.column_of_bearing(b))
            segments.append(np.array([[u, 0.0], [u, float(calibration.height)]]))
        else:
            radii = np.array([0.0, calibration.r_max])
            x, y = calibration.pixel_of_bearing(np.array([b, b]), radii)
            segments.append(np.stack([x, y], axis=1))
    return segments


@dataclass
class _FrameBatch:
    """Frame-level values of up to :data:`BATCH_FRAMES` frames, each keyed by its row.

    :meth:`RerunSink._send_frames` sends them as columns: a few ``send_columns`` calls per
    batch instead of several ``log`` calls per frame.
    """

    log_time_ns: list[int] = field(default_factory=list)
    movement: list[int] = field(default_factory=list)  # -1: not a keyframe
    png: dict[int, bytes] = field(default_factory=dict)
    labels: dict[int, NDArray[np.uint8]] = field(default_factory=dict)  # (H, W) class ids
    detections: dict[int, dict[str, float]] = field(default_factory=dict)  # name -> bearing
    rejected: dict[int, list[tuple[float, str]]] = field(default_factory=dict)  # bearing, why
    bearings_deg: dict[str, dict[int, float]] = field(default_factory=dict)

    def add_row(self, log_time_ns: int, movement: int | None) -> int:
        """Start the row of one frame; return its index."""
        self.log_time_ns.append(log_time_ns)
        self.movement.append(-1 if movement is None else movement)
        return len(self.log_time_ns) - 1

    def timed(self, rows: Iterable[int]) -> Iterator[tuple[list[int], list[rr.TimeColumn]]]:
        """``rows`` split into keyframes (both timelines) and the other frames (log time only)."""
        rows = list(rows)
        key = [r for r in rows if self.movement[r] >= 0]
        other = [r for r in rows if self.movement[r] < 0]
        if key:
            yield key, [self._log_time(key), rr.TimeColumn(MOVEMENT, sequence=self._at(key))]
        if other:
            yield other, [self._log_time(other)]

    def _at(self, rows: list[int]) -> list[int]:
        return [self.movement[r] for r in rows]

    def _log_time(self, rows: list[int]) -> rr.TimeColumn:
        ns = np.array([self.log_time_ns[r] for r in rows], np.int64)
        return rr.TimeColumn(LOG_TIME, timestamp=ns.astype("datetime64[ns]"))


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
        Send the gathered frames with each movement (a followed log), not only in batches of
        ``BATCH_FRAMES``.
    """

    def __init__(self, rec: rr.RecordingStream, *, images: bool = True, live: bool = False) -> None:
        self.rec = rec
        self._live = live
        self.wants_images = True  # the keyframes' panoramas are shown either way
        self.wants_all_frames = images
        self._run: RunInfo | None = None
        self._rgb: dict[str, tuple[int, int, int]] = {}
        self._trajectory_fl: list[NDArray[np.float64]] = []
        self._doubtful: dict[str, str] = {}
        self._unconfirmed: dict[str, str] = {}
        self._last_movement: int | None = None
        self._truth_trajectory_fl: list[NDArray[np.float64]] = []
        self._batch = _FrameBatch()

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

    def _set_time(self, log_time_ns: int, movement: int | None) -> None:
        self.rec.set_time(LOG_TIME, timestamp=np.datetime64(log_time_ns, "ns"))
        if movement is None:
            self.rec.reset_time()
            self.rec.set_time(LOG_TIME, timestamp=np.datetime64(log_time_ns, "ns"))
        else:
            self.rec.set_time(MOVEMENT, sequence=movement)

    # ------------------------------------------------------------------ frames
    def frame(self, frame: FrameRecord) -> None:
        assert self._run is not None
        movement = frame.keyframe[0] if frame.keyframe else None
        batch = self._batch
        row = batch.add_row(frame.log_time_ns, movement)
        if frame.png is not None:  # the logged PNG as is: no decoding, no raw pixels to copy
            batch.png[row] = frame.png
        elif frame.image_bgr is not None:
            self._set_time(frame.log_time_ns, movement)
            self.rec.log("camera/panorama", rr.Image(frame.image_bgr, color_model="BGR"))
        if frame.masks is not None:
            labels = np.zeros(next(iter(frame.masks.values())).shape, np.uint8)
            for i, name in enumerate(self._run.session.landmark_names(), start=1):
                mask = frame.masks.get(name)
                if mask is not None:
                    labels[mask] = i
            batch.labels[row] = labels
        seen = {
            d.name: d.bearing_rad
            for d in frame.detections.values()
            if d.visible and d.bearing_rad is not None
        }
        if frame.image_bgr is not None:
            batch.detections[row] = seen
            rejected = {
                (b.bearing_rad, why) for d in frame.detections.values() for b, why in d.rejected
            }
            if rejected:
                batch.rejected[row] = sorted(rejected)
        for name, b in seen.items():
            batch.bearings_deg.setdefault(name, {})[row] = math.degrees(b)
        if len(batch.log_time_ns) >= BATCH_FRAMES:
            self._send_frames()

    def _send_frames(self) -> None:
        """Send the gathered frames' entities as columns and start a new batch."""
        assert self._run is not None
        cal = self._run.session.calibration
        batch, send = self._batch, self.rec.send_columns
        for rows, times in batch.timed(batch.png):
            blobs = [batch.png[r] for r in rows]
            columns = rr.EncodedImage.columns(blob=blobs, media_type=["image/png"] * len(rows))
            send("camera/panorama", indexes=times, columns=columns)
        for rows, times in batch.timed(batch.labels):
            buffers = [batch.labels[r].ravel() for r in rows]
            send("camera/panorama/masks", times, rr.SegmentationImage.columns(buffer=buffers))
        for rows, times in batch.timed(batch.detections):
            if cal is None:  # frames come with a camera only (the runner refuses others)
                break
            seen = [batch.detections[r] for r in rows]
            strips = rr.LineStrips2D.columns(
                strips=[s for d in seen for s in detection_segments(cal, d.values())],
                colors=[self._rgb[n] for d in seen for n in d],
                labels=[f"{n} {math.degrees(b):.1f}°" for d in seen for n, b in d.items()],
            )
            send("camera/panorama/detections", times, strips.partition([len(d) for d in seen]))
        for rows, times in batch.timed(batch.rejected):
            if cal is None:
                break
            gone = [batch.rejected[r] for r in rows]
            strips = rr.LineStrips2D.columns(
                strips=[s for g in gone for s in detection_segments(cal, [b for b, _ in g])],
                labels=[f"rejected: {why}" for g in gone for _, why in g],
            )
            send("camera/panorama/rejected", times, strips.partition([len(g) for g in gone]))
        for name, values in batch.bearings_deg.items():
            for rows, times in batch.timed(values):
                degrees = rr.Scalars.columns(scalars=[values[r] for r in rows])
                send(f"bearings/{name}", indexes=times, columns=degrees)
        self._batch = _FrameBatch()

    # ------------------------------------------------------------------ movements
    def movement(self, record: MovementRecord) -> None:
        assert self._run is not None
        run = self._run
        if self._live and self._batch.log_time_ns:
            self._send_frames()
        self._set_time(record.log_time_ns, record.index)
        self._last_movement = record.index
        log = self.rec.log
        if not record.ok:
            log("log", rr.TextLog(f"movement {record.index}: {record.status}", level="WARN"))
            return
        for name, reason in record.skipped_landmarks.items():
            text = f"movement {record.index}: {name} skipped: {reason}"
            log("log", rr.TextLog(text, level="INFO"))
        self._log_joint(record)
        self._log_fr(record, run.session)
        self._log_fl(record, run)

    def association(self, record: AssociationRecord) -> None:
        if self._live and self._batch.log_time_ns:
            self._send_frames()
        # with the last movement on its timeline: logged after it, the final map wins there
        self._set_time(record.log_time_ns, self._last_movement)
        self.rec.log("log", rr.TextLog(record.text(), level="INFO"))
        for name, why in record.retracted.items():
            self.rec.log("log", rr.TextLog(f"with the final map, {name} {why}", level="WARN"))
            self._doubtful.pop(name, None)
            self._unconfirmed.pop(name, None)
        for name, why in record.named_at_end.items():
            self.rec.log("log", rr.TextLog(f"with the final map, {name} {why}", level="INFO"))
        if record.estimates is not None and self._run is not None:
            names = [n for n in record.estimates if n not in self._run.session.reference]
            self._log_map(record.estimates, names)
            self._log_errors(record.estimates, names, self._run)
        for label, text in record.reports.items():
            self.rec.log("log", rr.TextLog(f"{label} with the final map: {text}", level="WARN"))

    def _log_joint(self, record: MovementRecord) -> None:
        """Placement, residuals, noise estimate and re-initialization (joint estimator only)."""
        log = self.rec.log
        if record.placement:
            text = f"movement {record.index}: placed by {record.placement}"
            log("log", rr.TextLog(text, level="INFO"))
        if record.divergence:
            text = f"movement {record.index}: map re-initialized: {record.divergence}"
            log("log", rr.TextLog(text, level="WARN"))
        res = [r for pair in record.residuals_rad.values() for r in pair if r is not None]
        if res:
            log("residuals/rms_deg", rr.Scalars(math.degrees(math.sqrt(np.mean(np.square(res))))))
        if record.bearing_noise_rad is not None:
            log("residuals/noise_deg", rr.Scalars(math.degrees(record.bearing_noise_rad)))

    def _log_fr(self, record: MovementRecord, session: Session) -> None:
        log = self.rec.log
        for name in session.landmark_names():
            particles = record.particles_fr.get(name)
            cones = record.cones_fr.get(name)
            if cones is None:
                log(f"fr/cones/{name}", rr.Clear(recursive=False))
            else:
                reach = 1.5 if particles is None else 1.5 * float(np.abs(particles).max()) + 0.5
                outlines = [
                    shorten(c, apex, reach) for c, apex in zip(cones, FR_APEXES, strict=True)
                ]
                log(f"fr/cones/{name}", rr.LineStrips2D(outlines, colors=[self._rgb[name]]))
            if particles is None:
                log(f"fr/particles/{name}", rr.Clear(recursive=False))
            else:
                log(
                    f"fr/particles/{name}",
                    rr.Points2D(
                        particles, colors=[self._rgb[name]], radii=rr.Radius.ui_points(2.0)
                    ),
                )

    def _log_fl(self, record: MovementRecord, run: RunInfo) -> None:
        log = self.rec.log
        for name, particles in record.particles_fl.items():
            log(
                f"map/particles/{name}",
                rr.Points2D(particles, colors=[self._rgb[name]], radii=rr.Radius.ui_points(1.5)),
            )
        if run.estimator == "joint":
            # its initializer's belief stops with the landmark's entry in the map
            for name in record.estimates.keys() - record.particles_fl.keys():
                log(f"map/particles/{name}", rr.Clear(recursive=False))
        names = [n for n in record.estimates if n not in run.session.reference]
        doubtful = record.doubtful_landmarks or {}
        self._doubtful = dict(doubtful)
        self._unconfirmed = dict(record.unconfirmed_landmarks or {})
        self._log_map(record.estimates, names)
        for name, why in doubtful.items():
            log("log", rr.TextLog(f"movement {record.index}: {name} doubtful: {why}", level="WARN"))
        for name, rays in record.named_from.items():
            moves = sorted({m for m, _, _ in rays})
            text = (
                f"movement {record.index}: {name} named from {len(rays)} detections "
                f"(movements {moves[0]}-{moves[-1]})"
            )
            log("log", rr.TextLog(text, level="INFO"))
        if record.rays_fl:
            measured = list(record.rays_fl)
            log(
                "map/rays",
                rr.LineStrips2D(
                    [record.rays_fl[n] for n in measured],
                    colors=[self._rgb[n] for n in measured],
                    radii=rr.Radius.ui_points(0.75),
                    labels=measured,
                ),
            )
        if record.o1_fl is not None and record.o2_fl is not None:
            log(
                "map/observation_particles",
                rr.Points2D(
                    np.vstack([record.o1_fl, record.o2_fl]),
                    colors=[TRAJECTORY_RGB],
                    radii=rr.Radius.ui_points(1.0),
                ),
            )
            self._trajectory_fl.append(np.array([record.o1_fl.mean(0), record.o2_fl.mean(0)]))
            self._log_path("map/trajectory", self._trajectory_fl, TRAJECTORY_RGB, "O")
        truth = run.truth
        if truth is None:
            return
        if record.truth_o1_world is not None and record.truth_o2_world is not None:
            ends = np.array([record.truth_o1_world, record.truth_o2_world])
            self._truth_trajectory_fl.append(truth.to_fl.apply(ends))
            self._log_path("map/truth/trajectory", self._truth_trajectory_fl, TRUTH_RGB, None)
        self._log_errors(record.estimates, names, run)

    def _log_map(self, estimates: Mapping[str, EstimateRecord], names: Sequence[str]) -> None:
        """The map's points (labelled, doubtful and unconfirmed names marked) and 80% ellipses."""
        log = self.rec.log
        status = {
            **{n: " (unconfirmed)" for n in self._unconfirmed},
            **{n: " (doubtful)" for n in self._doubtful},
        }
        if names:
            log(
                "map/estimates",
                rr.Points2D(
                    np.array([estimates[n].mean_fl for n in names]),
                    colors=[self._rgb[n] for n in names],
                    radii=rr.Radius.ui_points(5.0),
                    labels=[n + status.get(n, "") for n in names],
                ),
            )
        for n in names:
            log(
                f"map/ellipses/{n}",
                # its own hue and thicker than the particles, so the region shows over its own cloud
                rr.LineStrips2D(
                    [estimates[n].ellipse80_fl],
                    colors=[ELLIPSE_RGB],
                    radii=rr.Radius.ui_points(1.5),
                    labels=[f"{n} 80%"],
                ),
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
            self.rec.log(f"error/{n}", rr.Scalars(e))
        if errors:
            self.rec.log("error/mean", rr.Scalars(float(np.mean(list(errors.values())))))

    def _log_path(
        self,
        entity: str,
        segments: list[NDArray[np.float64]],
        rgb: tuple[int, int, int],
        label: str | None,
    ) -> None:
        points = np.vstack(segments)
        labels = None
        if label is not None:
            labels = [f"{label}{k}.{j + 1}" for k in range(len(segments)) for j in range(2)]
        self.rec.log(
            entity,
            rr.LineStrips2D(segments, colors=[rgb], radii=rr.Radius.ui_points(1.0)),
            rr.Points2D(points, colors=[rgb], radii=rr.Radius.ui_points(3.0), labels=labels),
        )

    def finish(self) -> None:
        """Send the frames still gathered; the caller flushes or disconnects the stream."""
        if self._run is not None and self._batch.log_time_ns:
            self._send_frames()
