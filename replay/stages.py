"""The offline stages: decode -> bearings -> FR initialization -> change of frame -> FL fusion.

:func:`run_log` streams one log through the stages in log-time order and hands typed records
(:mod:`replay.records`) to sinks. It reads frames, ``/robot/movement`` and the simulator's
truth in one pass, as they come, so a finished log
(:class:`data_schemas.mcap.processable.ProcessableLog`) and a log still being written
(:class:`data_schemas.mcap.follow.FollowedLog`) go through the same code. Frames are decoded only
where a
sink needs them (keyframes for the estimate; every frame for Rerun).
A movement is processed once its end keyframe and its end message have arrived; one that
cannot be used (missing keyframe, reference landmark not visible, degenerate
geometry) is skipped with its reason and processing goes on; the reason is in the movement's
record (so in the summary) and is logged as a warning on the ``bslam.replay`` logger, which
prints nothing unless the application configures it (the CLI does for one log). Landmarks of a
class that several catalog landmarks share get no bearing from the extractor (it never guesses
which blob is which); :mod:`pipeline.association.alike` associates the blobs with the map and
names the landmarks ``red#1``, ``red#2``, ...; what it cannot resolve is in each movement's
record, with a warning.
"""

from __future__ import annotations

import contextlib
import gc
import logging
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pybase64
from numpy.typing import NDArray

from data_schemas.errors import EstimationError, ImageError, MissingMetadataError, SchemaError
from data_schemas.mcap.open import LogSource, MessageLog, entered
from data_schemas.mcap.read import LogMessage
from data_schemas.registry import (
    BEARINGS_TOPIC,
    CAMERA_TOPIC,
    IMAGE_SCHEMA,
    MOVEMENT_TOPIC,
    ODOMETRY_POSE_TOPIC,
    image_encoding,
)
from data_schemas.session import Session, shared_classes, shared_reference_problem
from data_schemas.stamps import ns_from_stamp
from pipeline.association.alike import AlikeLandmarks
from pipeline.bearings import (
    BearingExtractor,
    Detection,
    TagExtractor,
    decode_frame,
    make_extractor,
)
from pipeline.estimate import LandmarkEstimate
from pipeline.estimators import associating
from pipeline.slam import MovementObservation, MovementResult, MovementStatus, skipped
from replay.estimation import estimator_for, joint_fields
from replay.plan import PLAN_TOPICS, MovementPlan
from replay.records import (
    AssociationRecord,
    EstimateRecord,
    FrameRecord,
    MethodConfig,
    MovementRecord,
    RunInfo,
    Sink,
)
from replay.truth import Truth, truth_from_scenario, truth_of_session

#: what the runner reads, in log order: frames, the movement plan, the simulator's truth
STREAM_TOPICS = (CAMERA_TOPIC, *PLAN_TOPICS)
#: handled frames kept in case a movement message names one after a later frame
_RECENT_FRAMES = 8
CREDIBLE_P = 0.8

logger = logging.getLogger("bslam.replay")
logger.addHandler(logging.NullHandler())  # quiet unless the application asks (CLI: show_skips)


def decode_image(schema: str, msg: dict[str, Any]) -> tuple[NDArray[np.uint8], bytes | None]:
    """A frame message, decoded as its channel's schema says (``registry.IMAGE_SCHEMA``).

    ``foxglove.CompressedImage`` holds a PNG file (its ``format`` says ``png``);
    ``foxglove.RawImage`` holds ``bgr8`` pixels (``encoding``, ``width``, ``height``, ``step``).

    Returns
    -------
    image_bgr : (H, W, 3) uint8
        The decoded frame.
    png : bytes or None
        The PNG file as logged (CompressedImage), None for a raw frame.

    Raises
    ------
    ImageError
        Not an image schema, data that is not base64, or a frame its decoder refuses (lossy,
        another schema's encoding, corrupt, wrong size).
    """
    encoding = image_encoding(schema)
    stated = str(msg.get("format" if encoding == "png" else "encoding", ""))
    # a known encoding under another schema: the frame contradicts its channel
    home = next((s for e, s in IMAGE_SCHEMA.items() if e == stated.lower()), schema)
    if home != schema:
        raise ImageError(
            f"{CAMERA_TOPIC}: a {schema} frame cannot hold {stated!r} frames (a {home} can)"
        )
    try:
        data = pybase64.b64decode(msg["data"], validate=True)  # SIMD; 3x the stdlib's speed
    except (KeyError, ValueError) as exc:
        raise ImageError(f"{CAMERA_TOPIC}: frame data is not base64 ({exc})") from None
    if encoding == "png":
        return decode_frame(data, stated), data
    image = decode_frame(
        data,
        stated,
        width=int(msg["width"]),
        height=int(msg["height"]),
        step=int(msg["step"]) if "step" in msg else None,
    )
    return image, None


def estimate_records(estimates: Mapping[str, LandmarkEstimate]) -> dict[str, EstimateRecord]:
    """A map's estimates as records: mean, covariance and closed 80% outline (FL)."""
    out = {}
    for name, e in estimates.items():
        outline = np.asarray(e.credible_ellipse(CREDIBLE_P), np.float64)
        out[name] = EstimateRecord(
            np.asarray(e.mean_fl, np.float64),
            np.asarray(e.cov_fl, np.float64),
            np.vstack([outline, outline[:1]]),
        )
    return out


def session_extractor(session: Session) -> BearingExtractor | TagExtractor | None:
    """The extractor of a session's frames (its camera and catalog); None without a camera."""
    cal = session.calibration
    if cal is None:
        return None
    return make_extractor(
        cal, session.landmarks, range_m=session.range_m, tag_dictionary=session.tag_dictionary
    )


def no_camera(name: str) -> MissingMetadataError:
    """The error of a log with frames whose session has no camera."""
    return MissingMetadataError(
        f"{name}: frames on /camera/panorama but the session has no camera "
        "(no calibration); a log without a camera carries /sensor/bearings instead"
    )


@dataclass
class _Keyframe:
    timestamp_ns: int
    log_time_ns: int
    detections: dict[str, Detection]


@dataclass
class _State:
    """Keyframes seen so far, which movements are done, and frames not yet handled.

    A frame is held (``pending``) until the next message says whether it is a keyframe: the
    recorder writes a movement message right after its keyframe, before the next frame.
    """

    keyframes: dict[tuple[int, str], _Keyframe] = field(default_factory=dict)
    done: set[int] = field(default_factory=set)
    last_log_time_ns: int = 0
    last_timestamp_ns: int = 0
    keys_at: dict[int, list[tuple[int, str]]] = field(default_factory=dict)
    pending: LogMessage | None = None
    recent: dict[int, LogMessage] = field(default_factory=dict)


class Runner:
    """One log through the stages to the sinks (see :func:`run_log`)."""

    def __init__(self, log: MessageLog, method: MethodConfig, sinks: Sequence[Sink]) -> None:
        self.log = log
        self.session: Session = log.session
        self.method = method
        self.sinks = list(sinks)
        self.plan = MovementPlan()
        scenario = self.session.scenario
        self.truth: Truth | None = (
            truth_from_scenario(scenario, self.session.reference) if scenario else None
        )
        shared = shared_reference_problem(self.session.landmarks, self.session.reference)
        if shared:
            raise EstimationError(f"{log.name}: {shared}")
        self._extractor = session_extractor(self.session)
        alike = shared_classes(self.session.landmarks)
        if alike and method.estimator == "paper":
            classes = ", ".join(f"{c} ({', '.join(n)})" for c, n in alike.items())
            raise EstimationError(
                f"{log.name}: landmarks that look alike ({classes}) are associated with the "
                "joint estimator only (the paper's filter cannot take a landmark's bearings "
                "from before it was named); use --estimator joint"
            )
        self.alike = AlikeLandmarks(self.session) if alike else None
        names = self.session.landmark_names()
        mapped = self.alike.landmarks(names) if self.alike is not None else names
        self.slam = estimator_for(method, self.session, mapped)
        self.all_frames = any(s.wants_all_frames for s in self.sinks)
        self.images = any(s.wants_images for s in self.sinks)
        self.state = _State()

    @property
    def extractor(self) -> BearingExtractor | TagExtractor:
        """Bearings from frames; a session without a camera has frames to refuse."""
        if self._extractor is None:
            raise no_camera(self.log.name)
        return self._extractor

    def run(self) -> None:
        info = RunInfo(self.log.name, self.session, self.method, self.truth)
        for sink in self.sinks:
            sink.start(info)
        try:
            for msg in self.log.messages(STREAM_TOPICS):
                self._message(msg)
            self._settle()
            for index in sorted(self.plan.keyframes):
                if index not in self.state.done:
                    self._movement(index)
            self._associate_final()
        finally:
            for sink in self.sinks:
                sink.finish()

    def _associate_final(self) -> None:
        """Landmarks that look alike: every keyframe's detections with the final map."""
        if self.alike is None:
            return
        final = self.alike.final(associating(self.slam))
        mapped = self.alike.landmarks(self.session.landmark_names())
        rebuilt = self.alike.rebuilt(
            final, lambda: associating(estimator_for(self.method, self.session, mapped))
        )
        if rebuilt is not None:  # the map built again from the first movement explains more
            logger.info(
                "%s: the map built again from the first movement with the final association's "
                "names: %d of %d detections named (before: %d)",
                self.log.name,
                rebuilt[2].explained(),
                len(final.detections),
                final.explained(),
            )
            self.alike, self.slam, final = rebuilt
        # the map once the log is processed: its rounds move points even when no name changes
        estimates = estimate_records(self.slam.estimates)
        record = AssociationRecord(
            self.state.last_timestamp_ns,
            self.state.last_log_time_ns,
            final.detections,
            final.reports,
            final.retracted,
            estimates,
            final.placed_by_matching,
            final.named_at_end,
            final.weak,
        )
        logger.info("%s: %s", self.log.name, record.text())
        for name, why in record.retracted.items():
            logger.warning("%s: with the final map, %s %s", self.log.name, name, why)
        for name, why in record.named_at_end.items():
            logger.info("%s: with the final map, %s %s", self.log.name, name, why)
        for name, why in record.weak.items():
            logger.warning("%s: with the final map, %s is weak: %s", self.log.name, name, why)
        for label, text in record.reports.items():
            logger.warning("%s: %s with the final map: %s", self.log.name, label, text)
        for sink in self.sinks:
            sink.association(record)

    def _message(self, msg: LogMessage) -> None:
        """One message in log order: hold a frame, grow the plan, run a finished movement."""
        if msg.topic == CAMERA_TOPIC:
            self._settle()
            self.state.pending = msg
            return
        doc = self._decoded(msg)
        movement = None if doc is None else self.plan.add(msg.topic, doc)
        if movement is None:
            return
        index, phase, t_ns = movement
        keys = self.state.keys_at.setdefault(t_ns, [])
        if (index, phase) not in keys:
            keys.append((index, phase))
        pending = self.state.pending
        if pending is not None and pending.publish_time_ns == t_ns:
            self._settle()  # the recorder's order: keyframe, then its movement message
        elif t_ns in self.state.recent:
            self._late_keyframe(index, phase, self.state.recent[t_ns])

    def _settle(self) -> None:
        """Handle the held frame, now that the plan says whether it is a keyframe."""
        msg, self.state.pending = self.state.pending, None
        if msg is None:
            return
        # a frame's publish time is its timestamp: without all frames, decode only keyframes
        t_ns = msg.publish_time_ns
        self.state.recent[t_ns] = msg
        if len(self.state.recent) > _RECENT_FRAMES:
            del self.state.recent[next(iter(self.state.recent))]
        keys = self.state.keys_at.get(t_ns, [])
        if not keys and not self.all_frames:
            return
        self.state.last_log_time_ns, self.state.last_timestamp_ns = msg.log_time_ns, t_ns
        doc = self._decoded(msg)
        if doc is None:
            return
        self._frame(msg.schema, doc, ns_from_stamp(doc["timestamp"]), msg.log_time_ns, keys)

    def _decoded(self, msg: LogMessage) -> dict[str, Any] | None:
        """The message's document; None, with one warning, for a message that does not decode
        when the log is read with ``--skip-corrupt`` (else the SchemaError stops the run)."""
        try:
            return msg.decode()
        except SchemaError as exc:
            if not getattr(self.log, "skip_corrupt", False):
                raise
            logger.warning("%s: skipped a message that does not decode: %s", self.log.name, exc)
            return None

    def _late_keyframe(self, index: int, phase: str, msg: LogMessage) -> None:
        """A movement message naming a frame handled before it (not the recorder's order)."""
        if index in self.state.done or (index, phase) in self.state.keyframes:
            return
        doc = self._decoded(msg)
        if doc is None:
            return
        image, _ = decode_image(msg.schema, doc)
        detections = self.extractor.extract(image)
        self.state.keyframes[(index, phase)] = _Keyframe(
            msg.publish_time_ns, msg.log_time_ns, detections
        )
        if phase == "end":
            self._movement(index)

    def _frame(
        self,
        schema: str,
        doc: dict[str, Any],
        t_ns: int,
        log_time_ns: int,
        keys: list[tuple[int, str]],
    ) -> None:
        image, png = decode_image(schema, doc)
        if self.images:
            found, masks = self.extractor.extract_with_masks(image)
        else:
            found, masks = self.extractor.extract(image), None
        detections = found
        frame = FrameRecord(
            timestamp_ns=t_ns,
            log_time_ns=log_time_ns,
            keyframe=keys[0] if keys else None,
            detections=detections,
            image_bgr=image if self.images else None,
            masks=masks,
            png=png if self.images else None,
        )
        for sink in self.sinks:
            sink.frame(frame)
        # two frames may share a time stamp (a turn too short to take a clock tick): the later
        # one is the keyframe of movements still to come, not of one already run
        for index, phase in keys:
            if index not in self.state.done:
                self.state.keyframes[index, phase] = _Keyframe(t_ns, log_time_ns, detections)
        for index, phase in keys:
            if phase == "end" and index not in self.state.done:
                self._movement(index)

    def _movement(self, index: int) -> None:
        self.state.done.add(index)
        start = self.state.keyframes.get((index, "start"))
        end = self.state.keyframes.get((index, "end"))
        names = self.session.landmark_names()
        bearings = {
            n: (
                None if start is None else start.detections[n].bearing_rad,
                None if end is None else end.detections[n].bearing_rad,
            )
            for n in names
        }
        ambiguous = {
            n: k.detections[n].reason
            for k in (start, end)
            if k is not None
            for n in names
            if k.detections[n].ambiguous
        }
        t_ns = end.timestamp_ns if end else self.state.last_timestamp_ns
        log_time_ns = end.log_time_ns if end else self.state.last_log_time_ns
        missing = [p for p, k in (("start", start), ("end", end)) if k is None]
        if missing:
            phases = self.plan.keyframes.get(index, {})
            why = " and ".join(
                f"no {p} keyframe" if p not in phases else f"{p} keyframe frame not in the log"
                for p in missing
            )
            record = MovementRecord(
                index, t_ns, log_time_ns, skipped(why), bearings, ambiguous_landmarks=ambiguous
            )
        else:
            assert start is not None and end is not None
            obs = MovementObservation(
                index,
                {n: b for n, (b, _) in bearings.items() if b is not None},
                {n: b for n, (_, b) in bearings.items() if b is not None},
                self.plan.turns_rad.get(index),
                self.plan.distances_m.get(index),
            )
            assoc = None
            if self.alike is not None:
                obs, assoc = self.alike.observe(
                    index,
                    (start.detections, end.detections),
                    obs.turn_rad,
                    obs.distance_m,
                    associating(self.slam),
                )
            result = self.slam.process_movement(obs)
            if self.alike is not None and assoc is not None:
                self.alike.after(assoc, result, associating(self.slam))
                bearings = {n: b for n, b in bearings.items() if n not in self.alike.alike}
                for name in self.alike.associator.names:
                    pair = (assoc.bearings_o1_rad.get(name), assoc.bearings_o2_rad.get(name))
                    if pair != (None, None):
                        bearings[name] = pair
                ambiguous = dict(assoc.unresolved)
            record = self._record(result, t_ns, log_time_ns, bearings, start, end)
            record = replace(record, ambiguous_landmarks=ambiguous)
            if assoc is not None:
                record = replace(
                    record,
                    not_visible=dict(assoc.not_visible),
                    named_landmarks=assoc.confirmed,
                    named_from=dict(assoc.history),
                    doubtful_landmarks=dict(assoc.doubtful),
                    unconfirmed_landmarks=dict(assoc.unconfirmed),
                )
        if not record.ok:
            logger.warning("%s: movement %d %s", self.log.name, index, record.status)
        if ambiguous:
            logger.warning(
                "%s: movement %d: %s unresolved (landmarks that look alike): %s",
                self.log.name,
                index,
                ", ".join(sorted(ambiguous)),
                "; ".join(ambiguous[k] for k in sorted(ambiguous)),
            )
        for sink in self.sinks:
            sink.movement(record)

    def _record(
        self,
        result: MovementResult,
        t_ns: int,
        log_time_ns: int,
        bearings: dict[str, tuple[float | None, float | None]],
        start: _Keyframe,
        end: _Keyframe,
    ) -> MovementRecord:
        ok = result.status == MovementStatus.OK
        return MovementRecord(
            index=result.index,
            timestamp_ns=t_ns,
            log_time_ns=log_time_ns,
            status=result.status,
            bearings_rad=bearings,
            skipped_landmarks=dict(result.skipped_landmarks),
            cones_fr=dict(result.cones_fr),
            particles_fr=dict(result.particles_fr),
            particles_fl=dict(result.belief_fl) if ok else {},
            o1_fl=result.o1_fl if ok else None,
            o2_fl=result.o2_fl if ok else None,
            estimates=estimate_records(result.estimates),
            truth_o1_world=self.plan.true_position(start.timestamp_ns),
            truth_o2_world=self.plan.true_position(end.timestamp_ns),
            **joint_fields(result),
        )


def run_log(log: LogSource, method: MethodConfig, sinks: Sequence[Sink]) -> None:
    """Run one log (a path, or a log already opened or followed) through the stages into ``sinks``.

    Each sink's ``finish`` is called, also after an error. A path is opened and closed here.

    Every object alive when the run starts (mostly the libraries' modules, classes and
    functions: about 70k once Rerun is imported) is moved out of the garbage collector's sight
    (``gc.freeze``) for the run, so that the full collections during the run do not walk it
    again. They are handed back to the collector when the run ends, so a process that runs
    many logs (tests, batch) leaks nothing that dies between runs.
    """
    gc.freeze()
    try:
        with contextlib.ExitStack() as stack:
            _run_one(entered(log, stack), method, sinks)
    finally:
        gc.unfreeze()


def driving_log(topics: Collection[str] | None, session: Session) -> bool:
    """Whether a log goes through :class:`replay.driving.DrivingRunner` (docs/design.md).

    A log with bearings (``/sensor/bearings``), or with odometry poses
    (``/robot/odometry_pose``) and no movement plan (``/robot/movement``), is a driving log;
    frames with a movement plan (stop-and-go) go through :class:`Runner`. ``topics`` None: a
    log still being written, its channels still to come: driving if its session has no camera.
    """
    if topics is None:
        return session.calibration is None
    odometry_only = ODOMETRY_POSE_TOPIC in topics and MOVEMENT_TOPIC not in topics
    return BEARINGS_TOPIC in topics or odometry_only


def _run_one(log: MessageLog, method: MethodConfig, sinks: Sequence[Sink]) -> None:
    """Stop-and-go frames through :class:`Runner`; a driving log (:func:`driving_log`) through
    :class:`replay.driving.DrivingRunner`, its bearings from ``/sensor/bearings`` or else from
    its frames."""
    from replay.driving import DrivingRunner, check_topics

    topics = getattr(log, "topics", None)  # None: a followed log, its channels still to come
    driving = driving_log(topics, log.session)
    if not driving:
        Runner(log, method, sinks).run()  # its messages are checked (and refused) first
        if topics is not None:
            check_topics(log.name, list(topics))
        return
    if topics is not None:
        check_topics(log.name, list(topics))
    truth = truth_of_session(log.session)
    info = RunInfo(log.name, log.session, method, truth, driving=True)
    frames = topics is not None and CAMERA_TOPIC in topics and BEARINGS_TOPIC not in topics
    DrivingRunner(log, method, sinks, info, frames=frames).run()
