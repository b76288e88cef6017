"""One simulated session, end to end: the real record loop against the simulated world.

:func:`simulate_to_file` is what ``bslam simulate``, ``bslam demo`` and the experiments run. It
serves a :class:`~recorder.sim.fake_khepera.FakeKhepera` on a pseudo-terminal (real serial I/O
through :class:`~recorder.robot.KheperaRobot`), renders frames with
:class:`~recorder.sim.camera.SimCamera` from the robot's true pose, plans moves with
:class:`~recorder.sim.planner.MovePlanner`, and records with
:func:`recorder.start.run_session` in virtual time: the same code path as ``bslam record``.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from data_schemas.session import LandmarkSpec
from recorder.clock import PacedClock, VirtualClock
from recorder.record import Progress, RecordResult, RecordSettings
from recorder.robot import RobotConfig
from recorder.sim.camera import SimCamera
from recorder.sim.fake_khepera import ActuationNoise, FakeKhepera
from recorder.sim.planner import MovePlanner
from recorder.sim.scenario import Scenario
from recorder.start import SessionFacts, run_session
from recorder.timebase import EpochClock


@dataclass(frozen=True)
class SimSettings:
    """How a scenario is simulated (beyond the scenario itself).

    Attributes
    ----------
    record : RecordSettings
        Frame rate while driving (virtual time), encoding, PNG level.
    turn_noise, distance_noise : float
        Actuation noise of the simulated robot: relative std of each turn / straight distance.
    speed : float or None
        Run at most this many times as fast as real time (:class:`~recorder.clock.PacedClock`),
        e.g. to follow the log live; None: as fast as possible. The log's messages are the same.
    """

    record: RecordSettings = field(default_factory=RecordSettings)
    turn_noise: float = 0.02
    distance_noise: float = 0.02
    speed: float | None = None


def simulate_to_file(
    scenario: Scenario,
    out: str | os.PathLike[str],
    *,
    settings: SimSettings | None = None,
    source: str = "scenario",
    progress: Callable[[Progress], None] | None = None,
) -> RecordResult:
    """Simulate ``scenario`` and write a complete log to ``out``.

    Parameters
    ----------
    scenario : Scenario
        Arena, landmarks, camera, noise and trajectory (its ``trajectory.seed`` seeds the moves,
        the robot's actuation noise and the camera noise).
    out : path
        MCAP log to write.
    settings : SimSettings, optional
        Frame rate, encoding, actuation noise (defaults: 5 Hz, PNG level 1, 2 %).
    source : str
        Where the scenario came from (built-in name or file), recorded as the camera source.
    progress : callable, optional
        Called after each movement.

    Returns
    -------
    RecordResult
        Movements and frames written.
    """
    s = settings or SimSettings()
    rng_plan, rng_robot, rng_camera = (
        np.random.default_rng(seq)
        for seq in np.random.SeedSequence(scenario.trajectory.seed).spawn(3)
    )
    base = VirtualClock() if s.speed is None else PacedClock(s.speed)
    clock = EpochClock(base)
    fake = FakeKhepera(
        base,
        rng_robot,
        initial_pose_world=scenario.trajectory.start_world,
        noise=ActuationNoise(s.turn_noise, s.distance_noise),
    )
    camera = SimCamera.from_scenario(scenario, fake.pose_world, rng_camera)
    planner = MovePlanner(scenario, fake.pose_world, rng_plan)
    facts = SessionFacts(
        camera_source=f"simulated ({source})",
        calibration=scenario.calibration(),
        landmarks=[LandmarkSpec(lm.name, lm.color, bands=lm.bands) for lm in scenario.landmarks],
        reference=scenario.reference,
        vision_error_rad=scenario.vision_error_rad,
        scenario=scenario.to_dict(),
        extra={
            "recorder": {"png_level": s.record.png_level},
            "simulation": {
                "seed": scenario.trajectory.seed,
                "turn_noise": s.turn_noise,
                "distance_noise": s.distance_noise,
            },
        },
    )
    with fake.serve_pty() as server:
        config = RobotConfig(port=server.path, model="khepera2 (simulated)")
        return run_session(
            out,
            config,
            camera,
            clock,
            facts,
            planner,
            s.record,
            ground_truth=fake.pose_world,
            progress=progress,
        )
