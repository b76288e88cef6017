"""The offline stages: decode -> bearings -> FR initialization -> change of frame -> FL fusion.

:func:`run_log` streams one log through the stages in log-time order and hands typed records
(:mod:`replay.records`) to sinks. Frames are decoded only where a sink needs them (keyframes
for the estimate; every frame for Rerun). A movement is processed when its end keyframe
arrives; one that cannot be used (missing keyframe, reference landmark not visible, degenerate
geometry) is skipped with its reason and processing goes on; the reason is in the movement's
record (so in the summary) and is logged as a warning on the ``bslam.replay`` logger, which
prints nothing unless the application configures it (the CLI does for one log). Landmarks of a
class that several catalog landmarks share are ambiguous: they get no bearing (the extractor
never guesses which blob is which), and each movement's record lists them, with a warning.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pybase64
from numpy.typing import NDArray

from data_schemas.errors import EstimationError, ImageError
from data_schemas.session import Session, shared_reference_problem
from data_schemas.stamps import ns_from_stamp
from pipeline.bearings import BearingExtractor, Detection, decode_frame
from pipeline.slam import BearingSlam, MovementObservation, MovementResult
from replay.logs import ProcessableLog
from replay.plan import MovementPlan, read_plan
from replay.records import (
    EstimateRecord,
    FrameRecord,
    MethodConfig,
    MovementRecord,
    RunInfo,
    Sink,
)
from replay.truth import Truth, truth_from_scenario

CAMERA_TOPIC = "/camera/panorama"
CREDIBLE_P = 0.8

logger = logging.getLogger("bslam.replay")
logger.addHandler(logging.NullHandler())  # quiet unless the application asks (CLI: show_skips)


def decode_image(msg: dict[str, Any]) -> tuple[NDArray[np.uint8], bytes | None]:
    """A ``foxglove.CompressedImage`` (png) or ``foxglove.RawImage`` (bgr8) frame message.

    Returns
    -------
    image_bgr : (H, W, 3) uint8
        The decoded frame.
    png : bytes or None
        The PNG file as logged (CompressedImage), None for a raw frame.
    """
    try:
        data = pybase64.b64decode(msg["data"], validate=True)  # SIMD; 3x the stdlib's speed
    except (KeyError, ValueError) as exc:
        raise ImageError(f"/camera/panorama: frame data is not base64 ({exc})") from None
    if "format" in msg:
        fmt = str(msg["format"])
        return decode_frame(data, fmt), data if fmt.lower() == "png" else None
    image = decode_frame(
        data,
        str(msg.get("encoding", "")),
        width=int(msg["width"]),
        height=int(msg["height"]),
        step=int(msg["step"]) if "step" in msg else None,
    )
    return image, None


def _estimate_record(
    mean: NDArray[np.float64], cov: NDArray[np.float64], ellipse: Any
) -> EstimateRecord:
    outline = np.asarray(ellipse, np.float64)
    return EstimateRecord(
        np.asarray(mean, np.float64), np.asarray(cov, np.float64), np.vstack([outline, outline[:1]])
    )


@dataclass
class _Keyframe:
    timestamp_ns: int
    log_time_ns: int
    detections: dict[str, Detection]


@dataclass
class _State:
    """Keyframes seen so far, and which movements are done."""

    keyframes: dict[tuple[int, str], _Keyframe] = field(default_factory=dict)
    done: set[int] = field(default_factory=set)
    last_log_time_ns: int = 0
    last_timestamp_ns: int = 0


class Runner:
    """One log through the stages to the sinks (see :func:`run_log`)."""

    def __init__(self, log: ProcessableLog, method: MethodConfig, sinks: Sequence[Sink]) -> None:
        self.log = log
        self.session: Session = log.session
        self.method = method
        self.sinks = list(sinks)
        self.plan: MovementPlan = read_plan(log)
        scenario = self.session.scenario
        self.truth: Truth | None = (
            truth_from_scenario(scenario, self.session.reference) if scenario else None
        )
        shared = shared_reference_problem(self.session.landmarks, self.session.reference)
        if shared:
            raise EstimationError(f"{log.name}: {shared}")
        self.extractor = BearingExtractor(self.session.calibration, self.session.landmarks)
        self.slam = BearingSlam(
            self.session.landmark_names(),
            self.session.reference,
            vision_error_rad=self.session.vision_error_rad,
            prior=method.prior_name,
            n_r=method.n_r,
            n_l=method.n_l,
            rng=np.random.default_rng(method.seed),
        )
        self.all_frames = any(s.wants_all_frames for s in self.sinks)
        self.images = any(s.wants_images for s in self.sinks)
        self.state = _State()

    def run(self) -> None:
        info = RunInfo(self.log.name, self.session, self.method, self.truth)
        for sink in self.sinks:
            sink.start(info)
        try:
            self._frames()
        finally:
            for sink in self.sinks:
                sink.finish()

    def _frames(self) -> None:
        keys_at = self.plan.keys_at()
        # a frame's publish time is its timestamp: without all frames, read only keyframes
        only = None if self.all_frames else keys_at
        for msg in self.log.messages([CAMERA_TOPIC], publish_times_ns=only):
            doc = msg.decode()
            t_ns = ns_from_stamp(doc["timestamp"])
            keys = keys_at.get(t_ns, [])
            self.state.last_log_time_ns, self.state.last_timestamp_ns = msg.log_time_ns, t_ns
            if not keys and not self.all_frames:
                continue
            self._frame(doc, t_ns, msg.log_time_ns, keys)
        for index in sorted(self.plan.keyframes):
            if index not in self.state.done:
                self._movement(index)

    def _frame(
        self, doc: dict[str, Any], t_ns: int, log_time_ns: int, keys: list[tuple[int, str]]
    ) -> None:
        image, png = decode_image(doc)
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
        for key in keys:
            self.state.keyframes[key] = _Keyframe(t_ns, log_time_ns, detections)
        for index, phase in keys:
            if phase == "end":
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
                index, t_ns, log_time_ns, f"skipped: {why}", bearings, ambiguous_landmarks=ambiguous
            )
        else:
            assert start is not None and end is not None
            obs = MovementObservation(
                index,
                {n: b for n, (b, _) in bearings.items() if b is not None},
                {n: b for n, (_, b) in bearings.items() if b is not None},
            )
            result = self.slam.process_movement(obs)
            record = self._record(result, t_ns, log_time_ns, bearings, start, end)
            record = replace(record, ambiguous_landmarks=ambiguous)
        if not record.ok:
            logger.warning("%s: movement %d %s", self.log.name, index, record.status)
        if ambiguous:
            logger.warning(
                "%s: movement %d: %s not used (landmarks that look alike, no association)",
                self.log.name,
                index,
                ", ".join(sorted(ambiguous)),
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
        ok = result.status == "ok"
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
            estimates={
                n: _estimate_record(e.mean_fl, e.cov_fl, e.credible_ellipse(CREDIBLE_P))
                for n, e in result.estimates.items()
            },
            truth_o1_world=self.plan.true_position(start.timestamp_ns),
            truth_o2_world=self.plan.true_position(end.timestamp_ns),
        )


def run_log(
    log: str | os.PathLike[str] | ProcessableLog, method: MethodConfig, sinks: Sequence[Sink]
) -> None:
    """Run one log (a path, or a log already opened) through the stages into ``sinks``.

    Each sink's ``finish`` is called, also after an error. A path is opened and closed here.
    """
    if isinstance(log, ProcessableLog):
        Runner(log, method, sinks).run()
        return
    with ProcessableLog(log) as opened:
        Runner(opened, method, sinks).run()
