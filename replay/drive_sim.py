"""A simulated driving robot's log: :mod:`pipeline.driving.simulate` written as a bslam log.

The session has no camera: the 360-degree sensor's bearings go on ``/sensor/bearings``, the
wheel odometry on ``/robot/odometry_pose``, the true poses on ``/sim/ground_truth`` and the
true landmark positions in the session's ``truth`` (evaluation only). The log is written
through the importers' one path (:func:`replay.importers.write.import_log`: claimed, staged,
renamed when whole).
"""

from __future__ import annotations

import math
import os
import time
import uuid
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from data_schemas.mcap.writer import software_version
from data_schemas.registry import SIM_TRUTH_TOPIC
from data_schemas.session import SCHEMA_VERSION, session_from_doc
from data_schemas.stamps import stamp_from_ns
from pipeline.driving.simulate import DrivingRun, DrivingSpec, arenas, simulate_drive
from replay.importers.source import (
    ImportedLog,
    Message,
    SourceFile,
    bearing_set,
    in_time_order,
    odometry_pose,
)
from replay.importers.write import ImportResult, import_log


def drive_session(run: DrivingRun, vision_error_deg: float) -> dict[str, Any]:
    """The session document of a simulated drive (no robot, no camera), validated."""
    arena = run.arena
    assert arena is not None
    doc: dict[str, Any] = {
        "schema_version": SCHEMA_VERSION,
        "software_version": software_version(),
        "created_unix_ns": time.time_ns(),
        "session_id": uuid.uuid4().hex,
        "simulated": True,
        "landmarks": [{"name": n} for n in arena.landmarks_world],
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
    truth = [
        Message(
            int(t),
            SIM_TRUTH_TOPIC,
            {"timestamp": stamp_from_ns(int(t)), "x": p[0], "y": p[1], "heading": p[2]},
        )
        for t, p in zip(run.t_ns, run.truth_world.tolist(), strict=True)
    ]
    return in_time_order(odometry, bearings, truth)


@dataclass(frozen=True)
class SimulatedDrive:
    """A simulated drive as an importer's source (it reads no file)."""

    run: DrivingRun
    vision_error_deg: float

    @property
    def inputs(self) -> Sequence[SourceFile]:
        """No file: the drive is made in memory."""
        return ()

    def read(self) -> ImportedLog:
        messages = drive_messages(self.run)
        return ImportedLog(drive_session(self.run, self.vision_error_deg), messages, len(messages))


def simulate_drive_log(
    out: str | os.PathLike[str],
    *,
    arena: str = "square",
    duration_s: float = 120.0,
    seed: int = 0,
    vision_error_deg: float = 2.0,
    force: bool = False,
) -> ImportResult:
    """Simulate a drive in one of :func:`pipeline.driving.simulate.arenas` and write its log."""
    spec = DrivingSpec(duration_s=duration_s)
    run = simulate_drive(arenas()[arena], spec, np.random.default_rng(seed))
    assert math.isfinite(vision_error_deg)
    return import_log(SimulatedDrive(run, vision_error_deg), out, force=force)
