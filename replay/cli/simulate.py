"""``bslam simulate``: the real recorder against the simulated Khepera (pty) and camera."""

from __future__ import annotations

import click


@click.command("simulate")
@click.option(
    "--scenario",
    "scenario_arg",
    required=True,
    help="Scenario JSON file, or a built-in name (paper, paper_omni).",
)
@click.option("--out", required=True, type=click.Path(dir_okay=False), help="Log to write.")
@click.option("--seed", type=int, default=None, help="Replaces the scenario's trajectory.seed.")
@click.option(
    "--rate",
    "frame_rate_hz",
    type=click.FloatRange(min=0, min_open=True),
    default=5.0,
    show_default=True,
    help="Frames per second while driving (virtual time).",
)
@click.option(
    "--png-level", type=click.IntRange(0, 3), default=1, show_default=True, help="PNG level."
)
@click.option(
    "--turn-noise",
    type=click.FloatRange(min=0),
    default=0.02,
    show_default=True,
    help="Actuation noise: relative std of each turn.",
)
@click.option(
    "--distance-noise",
    type=click.FloatRange(min=0),
    default=0.02,
    show_default=True,
    help="Actuation noise: relative std of each straight distance.",
)
def simulate(
    scenario_arg: str,
    out: str,
    seed: int | None,
    frame_rate_hz: float,
    png_level: int,
    turn_noise: float,
    distance_noise: float,
) -> None:
    """Simulate a session: the same record loop as `bslam record`, in virtual time.

    The robot is a simulated Khepera served on a pseudo-terminal (real serial I/O), the camera
    renders the scenario from the robot's true pose, and `/sim/ground_truth` holds that pose at
    every frame.
    """
    import numpy as np

    from data_schemas.session import LandmarkSpec
    from recorder.clock import VirtualClock
    from recorder.record import CommandSink, RecordSettings, Rig
    from recorder.robot import KheperaRobot, RobotConfig
    from recorder.session import build_session_doc
    from recorder.sim.camera import SimCamera
    from recorder.sim.fake_khepera import ActuationNoise, FakeKhepera
    from recorder.sim.planner import MovePlanner
    from recorder.sim.scenario import BUILTIN_SCENARIOS, builtin_scenario, load_scenario
    from recorder.timebase import EpochClock
    from replay.cli.recording import run_recording

    if scenario_arg in BUILTIN_SCENARIOS:
        scenario = builtin_scenario(scenario_arg)
    else:
        scenario = load_scenario(scenario_arg)
    if seed is not None:
        scenario = scenario.with_seed(seed)
    rng_plan, rng_robot, rng_camera = (
        np.random.default_rng(s) for s in np.random.SeedSequence(scenario.trajectory.seed).spawn(3)
    )
    base = VirtualClock()
    clock = EpochClock(base)
    fake = FakeKhepera(
        base,
        rng_robot,
        initial_pose_world=scenario.trajectory.start_world,
        noise=ActuationNoise(turn_noise, distance_noise),
    )
    camera = SimCamera.from_scenario(scenario, fake.pose_world, rng_camera)
    planner = MovePlanner(scenario, fake.pose_world, rng_plan)
    sink = CommandSink()
    with fake.serve_pty() as server:
        config = RobotConfig(port=server.path, model="khepera2 (simulated)")
        with KheperaRobot.open(config, clock, on_exchange=sink) as robot:
            robot.version()
            doc = build_session_doc(
                created_unix_ns=clock.start_wall_ns,
                robot=config.session_dict(),
                camera_source=f"simulated ({scenario_arg})",
                calibration=scenario.calibration(),
                frame_rate_hz=frame_rate_hz,
                encoding="png",
                landmarks=[LandmarkSpec(lm.name, lm.color) for lm in scenario.landmarks],
                reference=scenario.reference,
                vision_error_rad=scenario.vision_error_rad,
                scenario=scenario.to_dict(),
                extra={
                    "recorder": {"png_level": png_level},
                    "simulation": {
                        "seed": scenario.trajectory.seed,
                        "turn_noise": turn_noise,
                        "distance_noise": distance_noise,
                    },
                },
            )
            rig = Rig(robot, sink, camera, clock, ground_truth=fake.pose_world)
            settings = RecordSettings(frame_rate_hz=frame_rate_hz, png_level=png_level)
            run_recording(out, doc, rig, planner, settings, total=len(planner))
