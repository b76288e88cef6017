"""Start a recording session from Python: the set-up shared by ``bslam record`` and the simulator.

:func:`run_session` opens the robot (it must answer before the log exists), builds the session
document, assembles the :class:`~recorder.record.Rig` and records every move into ``out``;
:func:`recorder.sim.simulate.simulate_to_file` calls it with the simulated robot and camera.
:func:`record_robot_session` is ``bslam record``: calibration and landmark files in, a real
Khepera and an OpenCV camera, random moves.

>>> from recorder.start import RobotSessionSpec, record_robot_session  # doctest: +SKIP
>>> spec = RobotSessionSpec(port="/dev/ttyUSB0", camera_source="0",
...                         calibration_file="camera.json", landmark_file="landmarks.json",
...                         moves=10, distance_m=(0.10, 0.25), seed=3)
>>> record_robot_session("run.mcap", spec)  # doctest: +SKIP
RecordResult(movements=10, frames=...)
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from data_schemas.calibration import Calibration
from data_schemas.session import LandmarkSpec
from recorder.camera import Camera
from recorder.moves import Move
from recorder.record import (
    CommandSink,
    GroundTruth,
    Progress,
    RecordResult,
    RecordSettings,
    Rig,
    record_to_file,
)
from recorder.robot import KheperaRobot, RobotConfig
from recorder.session import build_session_doc
from recorder.timebase import EpochClock


@dataclass(frozen=True)
class SessionFacts:
    """What the session document says besides the robot and the frame settings.

    Attributes
    ----------
    camera_source : str
        Device index, URL, file or image-sequence pattern (or ``"simulated (...)"``).
    calibration : Calibration
        How the camera's image positions map to bearings.
    landmarks : sequence of LandmarkSpec
        The landmark catalog.
    reference : (str, str)
        The reference pair (names in the catalog).
    vision_error_rad : float
        Bound eps on the bearing error, radians.
    scenario : dict, optional
        The simulation scenario (marks the session as simulated).
    extra : dict
        More top-level keys of the document (recorder or simulation settings).
    """

    camera_source: str
    calibration: Calibration
    landmarks: Sequence[LandmarkSpec]
    reference: tuple[str, str]
    vision_error_rad: float
    scenario: dict[str, Any] | None = None
    extra: dict[str, Any] = field(default_factory=dict)


def run_session(
    out: str | os.PathLike[str],
    config: RobotConfig,
    camera: Camera,
    clock: EpochClock,
    facts: SessionFacts,
    moves: Iterable[Move],
    settings: RecordSettings,
    *,
    ground_truth: GroundTruth | None = None,
    progress: Callable[[Progress], None] | None = None,
) -> RecordResult:
    """Open the robot, build the session document and record ``moves`` into ``out``.

    Parameters
    ----------
    out : path
        The MCAP log to write (created only once the robot has answered).
    config : RobotConfig
        Serial port and robot settings (recorded in the session document).
    camera : Camera
        Frame source (the caller opens and closes it).
    clock : EpochClock
        The session clock, shared by the robot, the camera and the writer.
    facts : SessionFacts
        Calibration, catalog, reference pair, eps, scenario and extra document keys.
    moves : iterable of Move
        The movements (a finite list, a random generator, a planner).
    settings : RecordSettings
        Frame rate, encoding and PNG level.
    ground_truth : callable, optional
        Simulation only: the true pose, written with every frame.
    progress : callable, optional
        Called after each movement.

    Raises
    ------
    RobotError, CameraError, SchemaError, LogError
        One line each; a stop signal raises :class:`~recorder.record.RecordingInterrupted`
        after the log is finished and indexed.
    """
    sink = CommandSink()
    with KheperaRobot.open(config, clock, on_exchange=sink) as robot:
        robot.version()  # the robot answers before the log is created
        doc = build_session_doc(
            created_unix_ns=clock.start_wall_ns,
            robot=config.session_dict(),
            camera_source=facts.camera_source,
            calibration=facts.calibration,
            frame_rate_hz=settings.frame_rate_hz,
            encoding=settings.encoding,
            landmarks=facts.landmarks,
            reference=facts.reference,
            vision_error_rad=facts.vision_error_rad,
            scenario=facts.scenario,
            extra=facts.extra,
        )
        rig = Rig(robot, sink, camera, clock, ground_truth=ground_truth)
        return record_to_file(out, doc, rig, moves, settings, progress=progress)


@dataclass(frozen=True)
class RobotSessionSpec:
    """A session on a real robot, as ``bslam record`` takes it.

    Attributes
    ----------
    port : str
        Serial port of the robot (``/dev/ttyUSB0``) or a pyserial URL.
    camera_source : str
        Device index, URL, video file or image-sequence pattern for ``cv2.VideoCapture``.
    calibration_file, landmark_file : path
        Camera calibration (``bslam.Calibration``) and landmark file (catalog, reference pair,
        ``vision_error_deg``).
    moves : int or None
        Number of movements; None records until a stop signal.
    distance_m : (float, float)
        Range of the random straight distances, metres.
    turn_rad : float, optional
        Fixed turn before each drive (default: uniform random).
    seed : int, optional
        Seed of the random turns and distances.
    robot : dict
        Keyword arguments of :class:`~recorder.robot.RobotConfig` besides the port (model,
        baudrate, mm_per_pulse, wheel_base_m).
    settings : RecordSettings
        Frame rate, encoding and PNG level.
    """

    port: str
    camera_source: str
    calibration_file: str | os.PathLike[str]
    landmark_file: str | os.PathLike[str]
    moves: int | None = 10
    distance_m: tuple[float, float] = (0.10, 0.25)
    turn_rad: float | None = None
    seed: int | None = None
    robot: dict[str, Any] = field(default_factory=dict)
    settings: RecordSettings = field(default_factory=RecordSettings)


def record_robot_session(
    out: str | os.PathLike[str],
    spec: RobotSessionSpec,
    *,
    progress: Callable[[Progress], None] | None = None,
) -> RecordResult:
    """Record a session on a real Khepera and camera (``bslam record``); see :func:`run_session`.

    The calibration and landmark files are read and checked before the robot or the camera is
    opened; the log is created only once both answer.
    """
    from recorder.camera import OpenCVCamera
    from recorder.clock import SystemClock
    from recorder.moves import random_moves
    from recorder.session import load_calibration_file, load_landmark_file

    calibration = load_calibration_file(spec.calibration_file)
    catalog = load_landmark_file(spec.landmark_file)
    config = RobotConfig(port=spec.port, **spec.robot)
    facts = SessionFacts(
        camera_source=spec.camera_source,
        calibration=calibration,
        landmarks=catalog.landmarks,
        reference=catalog.reference,
        vision_error_rad=catalog.vision_error_rad,
        extra={
            "recorder": {"png_level": spec.settings.png_level, "seed": spec.seed},
            **catalog.session_keys(),
        },
    )
    clock = EpochClock(SystemClock())
    camera = OpenCVCamera(spec.camera_source, calibration)
    try:
        plan = random_moves(
            np.random.default_rng(spec.seed), spec.moves, spec.distance_m, spec.turn_rad
        )
        return run_session(
            out, config, camera, clock, facts, plan, spec.settings, progress=progress
        )
    finally:
        camera.close()
