"""A driving robot's log through the driving estimator to the sinks.

A driving log has wheel odometry on ``/robot/odometry_pose`` and no movement plan, and its
bearings either on ``/sensor/bearings`` (a session without a camera: ``bslam import``, a
simulated drive) or in camera frames on ``/camera/panorama`` (``bslam import rosbag``,
``bslam import images``). :class:`DrivingRunner` reads them, with the truth
(``/sim/ground_truth``, ``/truth/robot_pose``) when the log has it, in one pass in log order,
feeds :class:`pipeline.driving.estimator.DrivingSlam`, and hands the sinks the records they
already know: each keyframe is a :class:`~replay.records.FrameRecord` (its bearings) and, with
the next keyframe, a :class:`~replay.records.MovementRecord` (``o1_fl``, ``o2_fl``: the two
keyframes in FL; ``rays_fl``: its bearings as rays; ``estimates``: the map). The map is in FL
once both reference landmarks are mapped (before that the records carry no FL positions); the
last record's estimates carry iSAM2's marginal covariances (the others none: marginals cost).

Frames: the first frame logged after odometry makes a keyframe is that keyframe's frame; its
bearings (the session's extractor, as :class:`replay.stages.Runner` uses it) go to the estimator,
which keeps one bearing per landmark per keyframe anyway. Other frames are decoded only for a
sink that wants every frame, and never reach the estimator (the map does not depend on the
sinks). A mapped landmark that the keyframe's camera cannot see (predicted outside a pinhole's
field of view) is reported as not visible there, not as missed.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from data_schemas.errors import EstimationError
from data_schemas.mcap.open import MessageLog
from data_schemas.registry import (
    BEARINGS_TOPIC,
    CAMERA_TOPIC,
    ODOMETRY_POSE_TOPIC,
    SIM_TRUTH_TOPIC,
    TRUTH_POSE_TOPIC,
)
from data_schemas.stamps import ns_from_stamp
from pipeline.association.predict import outside_view
from pipeline.bearings import Detection, camera_view_rad
from pipeline.driving.estimator import DrivingOptions, DrivingSlam, KeyframeResult
from pipeline.driving.odometry import compose
from pipeline.slam import MovementStatus, Placement
from replay.plan import MovementPlan
from replay.records import FrameRecord, MethodConfig, MovementRecord, RunInfo, Sink
from replay.stages import (
    decode_image,
    estimate_records,
    no_camera,
    session_extractor,
)

#: the robot's true pose: the simulator's, or an imported log's outside reference
TRUTH_POSE_TOPICS = (SIM_TRUTH_TOPIC, TRUTH_POSE_TOPIC)
DRIVING_TOPICS = (BEARINGS_TOPIC, ODOMETRY_POSE_TOPIC, *TRUTH_POSE_TOPICS)
#: Length (FL) of a ray drawn towards a landmark not in the map yet.
RAY_FL = 1.5
#: Why a mapped landmark has no bearing at a keyframe whose camera cannot see it.
OUTSIDE_VIEW = "outside the camera's field of view"
#: Keyframes between two progress lines on the ``bslam.replay`` logger (INFO).
PROGRESS_EVERY = 100

logger = logging.getLogger("bslam.replay")


def check_topics(name: str, topics: Sequence[str]) -> None:
    """Raise EstimationError unless a log with these topics has something to map.

    A log needs frames (``/camera/panorama``) or bearings with odometry.
    """
    if CAMERA_TOPIC in topics:
        return
    if BEARINGS_TOPIC not in topics:
        raise EstimationError(
            f"{name}: neither frames ({CAMERA_TOPIC}) nor bearings ({BEARINGS_TOPIC}): "
            "nothing to map; record with a camera, or import bearings (bslam import)"
        )
    if ODOMETRY_POSE_TOPIC not in topics:
        raise EstimationError(
            f"{name}: bearings without odometry ({ODOMETRY_POSE_TOPIC}): a driving robot's map "
            "needs its odometry; import it with the bearings (bslam import)"
        )


def driving_options(method: MethodConfig) -> DrivingOptions:
    """The estimator's options from a run's method (None fields keep the estimator's defaults)."""
    base = DrivingOptions()
    rule = base.keyframes
    if method.keyframe_distance_m is not None:
        rule = replace(rule, distance_m=method.keyframe_distance_m)
    if method.keyframe_turn_deg is not None:
        rule = replace(rule, turn_rad=math.radians(method.keyframe_turn_deg))
    wheel = base.wheel
    if method.odometry_std_per_m is not None:
        wheel = replace(wheel, trans_std_per_m=method.odometry_std_per_m)
    if method.odometry_heading_std_per_rad is not None:
        wheel = replace(wheel, rot_std_per_rad=method.odometry_heading_std_per_rad)
    return replace(
        base,
        keyframes=rule,
        wheel=wheel,
        prior=method.prior_name,
        window_keyframes=method.keyframe_window or None,
    )


def _detections(names: Sequence[str], r: KeyframeResult) -> dict[str, Detection]:
    """A keyframe's bearings as detections of every catalog landmark."""
    out = {}
    for name in names:
        ray = r.rays.get(name)
        if ray is None:
            out[name] = Detection(name, False, None, 0.0, 0.0, 0, 0, "not measured")
        else:
            out[name] = Detection(name, True, ray.bearing_rad, 0.0, 1.0, 0, 1, "")
    return out


class DrivingRunner:
    """One driving log through :class:`DrivingSlam` to the sinks (see the module doc).

    ``frames``: bearings come from the camera's frames (else from ``/sensor/bearings``).
    """

    def __init__(
        self,
        log: MessageLog,
        method: MethodConfig,
        sinks: Sequence[Sink],
        info: RunInfo,
        *,
        frames: bool = False,
    ) -> None:
        if method.estimator == "paper":
            raise EstimationError(
                f"{log.name}: the paper's filter takes stop-and-go movements; a driving log "
                "(bearings and odometry) is mapped by the driving estimator (--estimator joint)"
            )
        self.log = log
        self.session = log.session
        self.sinks = list(sinks)
        self.info = info
        self.slam = DrivingSlam(
            self.session.landmark_names(),
            self.session.reference,
            vision_error_rad=self.session.vision_error_rad,
            rng=np.random.default_rng(method.seed),
            options=driving_options(method),
        )
        self.truth = MovementPlan()
        self._held: MovementRecord | None = None
        self._log_time_ns: dict[int, int] = {}
        self.frames = frames
        self.view_rad = camera_view_rad(self.session.calibration) if frames else None
        self.all_frames = frames and any(s.wants_all_frames for s in self.sinks)
        self.images = frames and any(s.wants_images for s in self.sinks)
        #: keyframes made when the last frame was handed to the estimator
        self._framed = 0
        self.extractor = session_extractor(self.session) if frames else None
        if frames and self.extractor is None:
            raise no_camera(log.name)

    def run(self) -> None:
        for sink in self.sinks:
            sink.start(self.info)
        try:
            topics = (*DRIVING_TOPICS, CAMERA_TOPIC) if self.frames else DRIVING_TOPICS
            for msg in self.log.messages(topics):
                keyframe = self.slam.n_keyframes > self._framed
                if msg.topic == CAMERA_TOPIC and not (keyframe or self.all_frames):
                    continue
                doc = msg.decode()
                t_ns = ns_from_stamp(doc["timestamp"])
                if msg.topic == CAMERA_TOPIC:
                    self._frame(msg.schema, doc, t_ns, msg.log_time_ns, keyframe=keyframe)
                elif msg.topic == ODOMETRY_POSE_TOPIC:
                    pose = np.array([doc["x_m"], doc["y_m"], doc["theta_rad"]], np.float64)
                    self._log_time_ns[t_ns] = msg.log_time_ns
                    self._emit(self.slam.odometry(t_ns, pose))
                elif msg.topic == BEARINGS_TOPIC:
                    given = doc["bearings"]
                    self.slam.bearings(
                        t_ns,
                        {b["landmark"]: float(b["bearing_rad"]) for b in given},
                        {b["landmark"]: float(b["std_rad"]) for b in given if "std_rad" in b},
                    )
                else:
                    self.truth.add(SIM_TRUTH_TOPIC, doc)
            self._emit(self.slam.finish())
            if self.slam.n_keyframes == 0:
                raise EstimationError(
                    f"{self.log.name}: no odometry on {ODOMETRY_POSE_TOPIC}: no keyframe to map"
                )
            self._flush(final=True)
        finally:
            for sink in self.sinks:
                sink.finish()

    def _frame(
        self, schema: str, doc: dict[str, Any], t_ns: int, log_time_ns: int, *, keyframe: bool
    ) -> None:
        """One decoded frame: to the sinks; a keyframe's bearings to the estimator."""
        extractor = self.extractor
        assert extractor is not None
        image, png = decode_image(schema, doc)
        if self.images:
            found, masks = extractor.extract_with_masks(image)
        else:
            found, masks = extractor.extract(image), None
        k = self.slam.n_keyframes - 1
        frame = FrameRecord(
            t_ns,
            log_time_ns,
            (k, "start") if keyframe else None,
            found,
            image_bgr=image if self.images else None,
            masks=masks,
            png=png if self.images else None,
        )
        for sink in self.sinks:
            sink.frame(frame)
        if keyframe:
            self._framed = self.slam.n_keyframes
            seen = {n: d.bearing_rad for n, d in found.items() if d.bearing_rad is not None}
            self.slam.bearings(t_ns, {n: float(b) for n, b in seen.items()})

    def _outside_view(self, r: KeyframeResult) -> dict[str, str]:
        """Mapped landmarks without a bearing at keyframe ``r`` that its camera cannot see."""
        if self.view_rad is None:
            return {}
        points = self.slam.landmarks_m()
        names = [n for n in points if n not in r.rays]
        if not names:
            return {}
        d = np.array([points[n] for n in names]) - r.pose_m[:2]
        bearing = np.arctan2(d[:, 1], d[:, 0]) - r.pose_m[2]
        out = outside_view(bearing, np.zeros(len(names)), self.view_rad, n_std=0.0)
        return {n: OUTSIDE_VIEW for n, o in zip(names, out, strict=True) if o}

    def _emit(self, results: list[KeyframeResult]) -> None:
        for r in results:
            self._flush(final=False)
            self._held = self._record(r)
            if r.index % PROGRESS_EVERY == 0:
                mapped = len(self.slam.mapped)
                logger.info(
                    "%s: keyframe %d, %d of %d landmarks mapped",
                    self.log.name,
                    r.index,
                    mapped,
                    len(self.slam.names),
                )

    def _flush(self, *, final: bool) -> None:
        """Send the held record (the last one with the map's covariances)."""
        record, self._held = self._held, None
        if record is None:
            return
        if final:
            estimates = self.slam.estimates(covariance=True)
            record = replace(record, estimates=estimate_records(estimates))
        for sink in self.sinks:
            sink.movement(record)

    def _record(self, r: KeyframeResult) -> MovementRecord:
        names = self.slam.names
        log_time_ns = self._log_time_ns.pop(r.t_ns, r.t_ns)
        for t in [t for t in self._log_time_ns if t < r.t_ns]:
            del self._log_time_ns[t]
        if not self.frames:  # frames went to the sinks as they came
            frame = FrameRecord(r.t_ns, log_time_ns, (r.index, "start"), _detections(names, r))
            for sink in self.sinks:
                sink.frame(frame)
        ends = self.slam.to_fl(np.array([r.pose_m[:2], r.next_pose_m[:2]]))
        rays_fl = {} if ends is None else dict(self._rays_fl(r))
        return MovementRecord(
            index=r.index,
            timestamp_ns=r.t_ns,
            log_time_ns=log_time_ns,
            status=MovementStatus.OK,
            bearings_rad={n: (ray.bearing_rad, None) for n, ray in r.rays.items()},
            skipped_landmarks=dict(r.waiting),
            o1_fl=None if ends is None else ends[:1],
            o2_fl=None if ends is None else ends[1:],
            estimates=estimate_records(self.slam.estimates()),
            truth_o1_world=self.truth.true_position(r.t_ns),
            truth_o2_world=self.truth.true_position(self.slam.keyframe_times_ns[-1]),
            placement=Placement.ODOMETRY,
            map_unit_m=self.slam.unit_m,
            rays_fl=rays_fl,
            not_visible=self._outside_view(r),
        )

    def _rays_fl(self, r: KeyframeResult) -> Iterator[tuple[str, NDArray[np.float64]]]:
        """Each bearing of the keyframe as a segment (2, 2) FL from its sensor: to the
        landmark when mapped, else :data:`RAY_FL` long."""
        points = self.slam.landmarks_m()
        for name, ray in r.rays.items():
            sensor = compose(r.pose_m, ray.offset)
            a = float(sensor[2]) + ray.bearing_rad
            start = self.slam.to_fl(sensor[:2])
            assert start is not None
            if name in points:
                reach_m = float(np.hypot(*(points[name] - sensor[:2])))
            else:
                reach_m = RAY_FL * (self.slam.unit_m or 1.0)
            end_m = sensor[:2] + reach_m * np.array([math.cos(a), math.sin(a)])
            end = self.slam.to_fl(end_m)
            assert end is not None
            yield name, np.array([start, end])


def driving_summary(method: MethodConfig) -> dict[str, Any]:
    """The summary's ``method`` entries of the driving estimator: keyframe rule, wheel noise,
    the keyframes kept in iSAM2 (None: every one) and how many leave it at once."""
    o = driving_options(method)
    return {
        "keyframe_distance_m": o.keyframes.distance_m,
        "keyframe_turn_deg": round(math.degrees(o.keyframes.turn_rad), 9),
        "odometry_std_per_m": o.wheel.trans_std_per_m,
        "odometry_heading_std_per_rad": o.wheel.rot_std_per_rad,
        "odometry_heading_std_per_m": o.wheel.rot_std_per_m,
        "keyframe_window": o.window_keyframes,
        "keyframe_window_stride": o.window_stride,
    }
