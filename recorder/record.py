"""The record loop: turn, keyframe at rest, drive while capturing frames, keyframe; repeat.

For each movement ``i`` (see :func:`record_session`)::

    turn in place by turn_rad          (no frames; the robot is not at a keyframe pose yet)
    stop, keyframe at rest             /camera/panorama, /robot/odometry, /robot/movement start
    drive distance_m, capturing        /camera/panorama at frame_rate_hz
    stop, keyframe at rest             /camera/panorama, /robot/odometry, /robot/movement end

Every serial exchange goes to ``/robot/command`` (the robot's ``on_exchange``, see
:class:`CommandSink`), events and faults to ``/log``, and in simulation the true pose at every
frame to ``/sim/ground_truth``. Time stamps come from one clock (use
:class:`recorder.timebase.EpochClock`).

Stopping: :func:`stop_on_signals` turns SIGINT/SIGTERM into :class:`RecordingInterrupted`,
raised at the next safe point (between serial exchanges and writes, at least every ``poll_s``),
so no message is half written; a second signal raises at once. On any exception the loop logs
it to ``/log``, stops the motors (``D,0,0``) if it can, and re-raises; the caller's
``with LogWriter(...)`` then finishes an indexed file.
"""

from __future__ import annotations

import contextlib
import math
import os
import signal
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from types import FrameType
from typing import Any

from data_schemas.angles import wrap_rad
from data_schemas.errors import BslamError, LogError
from data_schemas.mcap.writer import LogWriter
from data_schemas.registry import (
    CAMERA_TOPIC,
    COMMAND_TOPIC,
    IMAGE_SCHEMA,
    MOVEMENT_TOPIC,
    ODOMETRY_TOPIC,
    ImageEncoding,
)
from data_schemas.stamps import stamp_from_ns
from recorder.camera import Camera
from recorder.clock import Clock
from recorder.frames import frame_message
from recorder.moves import Move
from recorder.png import check_level
from recorder.robot import Robot, drive, turn

#: ``foxglove.Log`` levels.
INFO, WARNING, ERROR = 2, 3, 4
LOG_NAME = "bslam.recorder"

#: A callable returning the true pose ``(x, y, heading)`` (m, rad, world frame) right now.
GroundTruth = Callable[[], Sequence[float]]


@dataclass(frozen=True)
class RecordSettings:
    """How the loop captures and stores frames (the ``bslam record``/``simulate`` options).

    Attributes
    ----------
    frame_rate_hz : float
        Frames per second captured while driving (keyframes come in addition).
    encoding : {"png", "bgr8"}
        Frame storage; see :mod:`recorder.frames`.
    png_level : int
        PNG level 0..3 (see :mod:`recorder.png`; ignored for ``bgr8``).
    poll_s : float
        Motion-status polling period, seconds (also the signal-check period).
    chunk_compression : {"", "zstd"}
        Log chunk compression (``--chunk-compression``; see :class:`LogWriter`).
    """

    frame_rate_hz: float = 5.0
    encoding: ImageEncoding = "png"
    png_level: int = 1
    poll_s: float = 0.05
    chunk_compression: str = ""

    def __post_init__(self) -> None:
        if not self.frame_rate_hz > 0:
            raise ValueError(f"frame rate must be > 0 Hz, got {self.frame_rate_hz}")
        if self.encoding not in IMAGE_SCHEMA:
            raise ValueError(f"encoding must be one of {sorted(IMAGE_SCHEMA)}, got {self.encoding}")
        check_level(self.png_level)
        if not self.poll_s > 0:
            raise ValueError(f"poll period must be > 0 s, got {self.poll_s}")


@dataclass(frozen=True)
class Progress:
    """Sent to the progress callback after each movement."""

    movements: int
    frames: int


@dataclass(frozen=True)
class RecordResult:
    """What a session recorded: completed movements and frames."""

    movements: int
    frames: int


class RecordingInterrupted(BaseException):
    """SIGINT or SIGTERM asked the recorder to stop (a BaseException, like KeyboardInterrupt)."""

    def __init__(self, signum: int) -> None:
        self.signum = signum
        super().__init__(f"recording stopped by {signal.Signals(signum).name}")


class _SignalFlag:
    """Pending stop request set by the signal handler, checked at safe points."""

    def __init__(self) -> None:
        self.signum: int | None = None

    def check(self) -> None:
        if self.signum is not None:
            raise RecordingInterrupted(self.signum)


_FLAG = _SignalFlag()


def check_stop() -> None:
    """Raise :class:`RecordingInterrupted` if a stop signal came (inside
    :func:`stop_on_signals`): a safe point of a recording loop."""
    _FLAG.check()


@contextlib.contextmanager
def stop_on_signals(
    signums: Iterable[int] = (signal.SIGINT, signal.SIGTERM),
) -> Iterator[None]:
    """Within the block, SIGINT/SIGTERM stop the recording cleanly (see module docstring).

    The first signal sets a flag that :func:`record_session` turns into
    :class:`RecordingInterrupted` at its next safe point; a second one raises immediately.
    Python's default SIGTERM would end the process without running ``finally`` blocks.
    """

    def handler(signum: int, frame: FrameType | None) -> None:
        if _FLAG.signum is not None:
            raise RecordingInterrupted(signum)
        _FLAG.signum = signum

    previous = {s: signal.signal(s, handler) for s in signums}
    _FLAG.signum = None
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
        _FLAG.signum = None


class CommandSink:
    """The robot's ``on_exchange``: holds ``/robot/command`` messages until a writer is attached.

    The robot is opened (and answers) before the log is created, so a wrong port never leaves an
    empty log behind; its first exchanges are written once the log exists.
    """

    def __init__(self) -> None:
        self._pending: list[dict[str, Any]] = []
        self._writer: LogWriter | None = None

    def attach(self, writer: LogWriter) -> None:
        """Write the held messages, then write each new one at once."""
        self._writer = writer
        pending, self._pending = self._pending, []
        for msg in pending:
            writer.write(COMMAND_TOPIC, msg)

    def __call__(self, msg: dict[str, Any]) -> None:
        if self._writer is None:
            self._pending.append(msg)
            return
        if self._writer.failed:
            return  # the log already raised its error; stopping the motors must still work
        self._writer.write(COMMAND_TOPIC, msg)


@dataclass(frozen=True)
class Rig:
    """What a session records from.

    Attributes
    ----------
    robot : Robot
        Open robot whose ``on_exchange`` is ``sink``.
    sink : CommandSink
        Writes the robot's ``/robot/command`` messages once the log exists.
    camera : Camera
        Frame source; its calibration is in the session document.
    clock : Clock
        The session clock (the writer's and the robot's).
    ground_truth : callable, optional
        Simulation only: the true pose now; written with every frame.
    """

    robot: Robot
    sink: CommandSink
    camera: Camera
    clock: Clock
    ground_truth: GroundTruth | None = None


@dataclass
class _Recorder:
    rig: Rig
    writer: LogWriter
    settings: RecordSettings
    frames: int = 0
    last_frame_ns: int | None = None

    def log(self, level: int, text: str) -> None:
        _FLAG.check()
        self.writer.write(
            "/log",
            {
                "timestamp": stamp_from_ns(self.rig.clock.monotonic_ns()),
                "level": level,
                "message": text,
                "name": LOG_NAME,
                "file": "",
                "line": 0,
            },
        )

    def frame(self) -> int:
        """Capture, write a frame (and the true pose in simulation); return its time stamp."""
        _FLAG.check()
        t_ns = self.rig.clock.monotonic_ns()
        image = self.rig.camera.read()
        encoding = self.settings.encoding
        msg = frame_message(image, t_ns, encoding=encoding, png_level=self.settings.png_level)
        self.writer.write(CAMERA_TOPIC, msg, schema=IMAGE_SCHEMA[encoding])
        if self.rig.ground_truth is not None:
            x, y, heading = self.rig.ground_truth()
            self.writer.write(
                "/sim/ground_truth",
                {
                    "timestamp": stamp_from_ns(t_ns),
                    "x": float(x),
                    "y": float(y),
                    "heading": wrap_rad(float(heading)),
                },
            )
        self.frames += 1
        self.last_frame_ns = t_ns
        return t_ns

    def frame_if_due(self) -> None:
        """``on_poll`` while driving: a frame every ``frame_period_ns``."""
        _FLAG.check()
        now = self.rig.clock.monotonic_ns()
        period_ns = round(1e9 / self.settings.frame_rate_hz)
        if self.last_frame_ns is None or now - self.last_frame_ns >= period_ns:
            self.frame()

    def keyframe(self, index: int, phase: str, move: Move) -> None:
        """At rest: keyframe, odometry, and the movement message pointing at the keyframe."""
        robot = self.rig.robot
        robot.stop()
        t_key = self.frame()
        left, right = robot.read_position_counters()
        now = stamp_from_ns(self.rig.clock.monotonic_ns())
        self.writer.write(
            ODOMETRY_TOPIC,
            {
                "timestamp": now,
                "left_pulses": left,
                "right_pulses": right,
                "mm_per_pulse": robot.config.mm_per_pulse,
            },
        )
        self.writer.write(
            MOVEMENT_TOPIC,
            {
                "timestamp": now,
                "index": index,
                "phase": phase,
                "keyframe_timestamp": stamp_from_ns(t_key),
                "turn_rad": move.turn_rad,
                "distance_m": move.distance_m,
            },
        )


def record_session(
    rig: Rig,
    writer: LogWriter,
    moves: Iterable[Move],
    settings: RecordSettings,
    *,
    progress: Callable[[Progress], None] | None = None,
) -> RecordResult:
    """Run the movement plan and record everything into ``writer``.

    Parameters
    ----------
    rig : Rig
        Robot, command sink (attached to ``writer`` here), camera, clock, ground truth.
    writer : LogWriter
        Open log; the caller finishes it (``with LogWriter(...)``), also after an error.
    moves : iterable of Move
        The plan; pulled one at a time (a simulator may plan from the true pose).
    settings : RecordSettings
        Frame rate, encoding, PNG level, polling period.
    progress : callable, optional
        Called with :class:`Progress` after each movement.

    Raises
    ------
    RecordingInterrupted
        SIGINT/SIGTERM (inside :func:`stop_on_signals`); the motors are stopped.
    BslamError
        Robot, camera or disk fault; logged to ``/log`` when possible, motors stopped.
    """
    rig.sink.attach(writer)
    rec = _Recorder(rig, writer, settings)
    poll = min(settings.poll_s, 1.0 / settings.frame_rate_hz)
    robot, clock, config = rig.robot, rig.clock, rig.robot.config
    done = 0
    try:
        rec.log(INFO, f"session started: robot {config.model} on {config.port}")
        for index, move in enumerate(moves):
            rec.log(
                INFO,
                f"movement {index}: turn {math.degrees(move.turn_rad):.1f} deg, "
                f"drive {move.distance_m:.3f} m",
            )
            turn(robot, config, move.turn_rad, clock, poll_s=poll, on_poll=_FLAG.check)
            rec.keyframe(index, "start", move)
            rec.last_frame_ns = clock.monotonic_ns()
            drive(robot, config, move.distance_m, clock, poll_s=poll, on_poll=rec.frame_if_due)
            rec.keyframe(index, "end", move)
            done += 1
            if progress is not None:
                progress(Progress(done, rec.frames))
        rec.log(INFO, f"session finished: {done} movements, {rec.frames} frames")
    except RecordingInterrupted as exc:
        _stop_after(rec, WARNING, f"{exc}; {done} movements complete")
        raise
    except BslamError as exc:
        _stop_after(rec, ERROR, f"fault after {done} movements: {exc}")
        raise
    except BaseException as exc:
        _stop_after(rec, ERROR, f"recorder crashed after {done} movements: {exc!r}")
        raise
    return RecordResult(done, rec.frames)


def _stop_after(rec: _Recorder, level: int, text: str) -> None:
    """Best effort after a failure: log it, stop the motors; never mask the original error."""
    _FLAG.signum = None  # the stop request is being honoured: do not raise it again
    if not rec.writer.failed:
        with contextlib.suppress(LogError):
            rec.log(level, text)
    with contextlib.suppress(BslamError):
        rec.rig.robot.stop()


def record_to_file(
    out: str | os.PathLike[str],
    session_doc: dict[str, Any],
    rig: Rig,
    moves: Iterable[Move],
    settings: RecordSettings,
    *,
    progress: Callable[[Progress], None] | None = None,
) -> RecordResult:
    """Create the log ``out``, run :func:`record_session` into it, finish the log.

    The one code path of ``bslam record`` and ``bslam simulate``. SIGINT/SIGTERM are handled
    (see :func:`stop_on_signals`) from before the log exists until it is finished, so a stop
    request always leaves an indexed file. ``session_doc`` is the session document
    (:func:`recorder.session.build_session_doc`); the other arguments are those of
    :func:`record_session`.
    """
    with (
        stop_on_signals(),
        LogWriter(
            out, session_doc, clock=rig.clock, compression=settings.chunk_compression
        ) as writer,
    ):
        return record_session(rig, writer, moves, settings, progress=progress)
