"""A simulated driving robot's log: :mod:`pipeline.driving.simulate` written as a bslam log.

Without a camera the session has no calibration and the 360-degree sensor's bearings go on
``/sensor/bearings``. With a camera (:class:`DriveCamera`: any calibration, e.g. a 60-degree
pinhole) the simulator's renderer (:func:`recorder.sim.render.render_panorama`) draws frames on
``/camera/panorama`` along the same drive instead: each landmark is a two-band coded cylinder
(:func:`band_codes`), a frame is rendered at the true pose of every ``frame_period_s``-th
sample and stamped :data:`FRAME_DELAY_NS` after it. Either way the wheel odometry goes on
``/robot/odometry_pose``, the true poses on ``/sim/ground_truth`` and the true landmark
positions in the session's ``truth`` (evaluation only). The log is written through the
importers' one path (:func:`replay.importers.write.import_log`: claimed, staged, renamed when
whole).
"""

from __future__ import annotations

import math
import os
import time
import uuid
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from itertools import permutations
from typing import Any

import numpy as np

from data_schemas.calibration import Calibration
from data_schemas.colors import COLOR_NAMES
from data_schemas.mcap.writer import software_version
from data_schemas.registry import CAMERA_TOPIC, SIM_TRUTH_TOPIC
from data_schemas.session import SCHEMA_VERSION, session_from_doc
from data_schemas.stamps import stamp_from_ns
from pipeline.driving.simulate import DrivingRun, DrivingSpec, arenas, simulate_drive
from recorder.frames import frame_message
from recorder.sim.render import RenderedFrame, render_panorama
from recorder.sim.world import Arena as SimArena
from recorder.sim.world import Landmark, SimWorld
from replay.importers.source import (
    ImportedLog,
    Message,
    SourceFile,
    bearing_set,
    in_time_order,
    odometry_pose,
)
from replay.importers.write import ImportResult, import_log

#: A frame's time stamp after the odometry sample whose true pose it is rendered at (ns): the
#: frame comes after that sample in the log (the robot moves 0.25 mm meanwhile at 0.25 m/s).
FRAME_DELAY_NS = 1_000_000


@dataclass(frozen=True)
class DriveCamera:
    """The camera of a simulated drive.

    Attributes
    ----------
    calibration : Calibration
        Camera model and image size (a pinhole's field of view is its focal length).
    frame_period_s : float
        Time between frames (a multiple of the drive's time step).
    landmark_radius_m, landmark_height_m : float
        Size of every landmark's cylinder.
    bearing_noise_rad : float
        Std of the drawn landmarks' bearing noise (truncated at the vision error bound).
    pixel_noise : float
        Std of the per-pixel noise, grey levels.
    """

    calibration: Calibration
    frame_period_s: float = 0.2
    landmark_radius_m: float = 0.05
    landmark_height_m: float = 0.3
    bearing_noise_rad: float = math.radians(0.5)
    pixel_noise: float = 2.0


def band_codes(n: int) -> list[tuple[str, str]]:
    """Two-band codes (top, bottom) of ``n`` landmarks, all different (at most 30)."""
    codes = list(permutations(COLOR_NAMES, 2))
    if n > len(codes):
        raise ValueError(f"{n} landmarks, but only {len(codes)} two-band codes")
    return codes[:n]


def drive_world(run: DrivingRun, camera: DriveCamera) -> SimWorld:
    """The renderer's world of a drive: each landmark a coded cylinder at its true position."""
    arena = run.arena
    assert arena is not None
    codes = band_codes(len(arena.landmarks_world))
    landmarks = tuple(
        Landmark(
            name,
            float(p[0]),
            float(p[1]),
            None,
            radius_m=camera.landmark_radius_m,
            height_m=camera.landmark_height_m,
            bands=code,
        )
        for (name, p), code in zip(arena.landmarks_world.items(), codes, strict=True)
    )
    x0, y0, x1, y1 = arena.area
    return SimWorld(SimArena(x1 - min(x0, 0.0), y1 - min(y0, 0.0)), landmarks)


def frame_every(run: DrivingRun, camera: DriveCamera) -> int:
    """A frame every this many odometry samples."""
    dt_s = float(run.t_ns[1] - run.t_ns[0]) * 1e-9 if len(run.t_ns) > 1 else 1.0
    return max(1, round(camera.frame_period_s / dt_s))


def drive_frames(
    run: DrivingRun, camera: DriveCamera, vision_error_rad: float, rng: np.random.Generator
) -> Iterator[tuple[int, RenderedFrame]]:
    """The drive's frames, one at a time: (time stamp ns, rendered frame with its truth)."""
    world = drive_world(run, camera)
    for i in range(0, len(run.t_ns), frame_every(run, camera)):
        x, y, heading = (float(v) for v in run.truth_world[i])
        frame = render_panorama(
            (x, y, heading),
            world,
            camera.calibration,
            rng,
            bearing_noise_rad=camera.bearing_noise_rad,
            vision_error_rad=vision_error_rad,
            pixel_noise=camera.pixel_noise,
        )
        yield int(run.t_ns[i]) + FRAME_DELAY_NS, frame


def drive_session(
    run: DrivingRun, vision_error_deg: float, camera: DriveCamera | None = None
) -> dict[str, Any]:
    """The session document of a simulated drive (no robot; a camera if given), validated."""
    arena = run.arena
    assert arena is not None
    if camera is None:
        catalog: list[dict[str, Any]] = [{"name": n} for n in arena.landmarks_world]
    else:
        codes = band_codes(len(arena.landmarks_world))
        catalog = [
            {"name": n, "bands": list(code)}
            for n, code in zip(arena.landmarks_world, codes, strict=True)
        ]
    doc: dict[str, Any] = {
        "schema_version": SCHEMA_VERSION,
        "software_version": software_version(),
        "created_unix_ns": time.time_ns(),
        "session_id": uuid.uuid4().hex,
        "simulated": True,
        "landmarks": catalog,
        "reference": list(arena.reference),
        "vision_error_deg": vision_error_deg,
        "truth": {
            "source": f"simulated drive in the {arena.name} arena",
            "landmarks": [
                {"name": n, "x_m": float(p[0]), "y_m": float(p[1])}
                for n, p in arena.landmarks_world.items()
            ],
        },
    }
    if camera is not None:
        doc["camera"] = {
            "source": "simulated drive",
            "calibration": camera.calibration.to_dict(),
            "encoding": "png",
            "frame_rate_hz": 1.0 / camera.frame_period_s,
        }
    session_from_doc(doc, what="simulated drive")
    return doc


def drive_messages(run: DrivingRun, bearing_std_rad: float | None = None) -> list[Message]:
    """Odometry, bearings and true poses of a simulated drive, in time order."""
    odometry = [
        odometry_pose(int(t), float(p[0]), float(p[1]), float(p[2]))
        for t, p in zip(run.t_ns, run.odometry, strict=True)
    ]
    std = {} if bearing_std_rad is None else {"std_rad": bearing_std_rad}
    bearings = [
        bearing_set(
            t,
            "simulated 360-degree sensor",
            [{"landmark": n, "bearing_rad": b, **std} for n, b in seen.items()],
        )
        for t, seen in run.bearing_sets
    ]
    truth = [_truth(int(t), p) for t, p in zip(run.t_ns, run.truth_world.tolist(), strict=True)]
    return in_time_order(odometry, bearings, truth)


def _truth(t_ns: int, pose: list[float]) -> Message:
    """The simulator's true pose (x m, y m, heading rad) at ``t_ns``."""
    doc = {"timestamp": stamp_from_ns(t_ns), "x": pose[0], "y": pose[1], "heading": pose[2]}
    return Message(t_ns, SIM_TRUTH_TOPIC, doc)


def camera_drive_messages(
    run: DrivingRun, camera: DriveCamera, vision_error_deg: float, seed: int
) -> Iterator[Message]:
    """Odometry, true poses and frames (PNG) of a simulated drive, in time order, one at a
    time (frames are rendered as they are written)."""
    rng = np.random.default_rng(seed)
    frames = (
        Message(t, CAMERA_TOPIC, frame_message(f.image_bgr, t, encoding="png"))
        for t, f in drive_frames(run, camera, math.radians(vision_error_deg), rng)
    )
    pending = next(frames, None)
    for t, p, q in zip(
        run.t_ns.tolist(), run.odometry.tolist(), run.truth_world.tolist(), strict=True
    ):
        while pending is not None and pending.t_ns < t:
            yield pending
            pending = next(frames, None)
        yield odometry_pose(t, *p)
        yield _truth(t, q)
    if pending is not None:  # frames after the last odometry sample
        yield pending
        yield from frames


@dataclass(frozen=True)
class SimulatedDrive:
    """A simulated drive as an importer's source (it reads no file): bearings, or a camera's
    frames rendered with ``seed``."""

    run: DrivingRun
    vision_error_deg: float
    camera: DriveCamera | None = None
    seed: int = 0

    @property
    def inputs(self) -> Sequence[SourceFile]:
        """No file: the drive is made in memory."""
        return ()

    def read(self) -> ImportedLog:
        session = drive_session(self.run, self.vision_error_deg, self.camera)
        if self.camera is None:
            messages = drive_messages(self.run)
            return ImportedLog(session, messages, len(messages))
        return ImportedLog(
            session,
            camera_drive_messages(self.run, self.camera, self.vision_error_deg, self.seed),
            2 * len(self.run.t_ns) + -(-len(self.run.t_ns) // frame_every(self.run, self.camera)),
        )


def simulate_drive_log(
    out: str | os.PathLike[str],
    *,
    arena: str = "square",
    duration_s: float = 120.0,
    seed: int = 0,
    vision_error_deg: float = 2.0,
    camera: DriveCamera | None = None,
    force: bool = False,
) -> ImportResult:
    """Simulate a drive in one of :func:`pipeline.driving.simulate.arenas` and write its log
    (bearings, or ``camera``'s frames)."""
    run = simulated_drive(arena, duration_s, seed)
    assert math.isfinite(vision_error_deg)
    return import_log(SimulatedDrive(run, vision_error_deg, camera, seed), out, force=force)


def simulated_drive(arena: str, duration_s: float, seed: int) -> DrivingRun:
    """The drive :func:`simulate_drive_log` writes."""
    spec = DrivingSpec(duration_s=duration_s)
    return simulate_drive(arenas()[arena], spec, np.random.default_rng(seed))
