"""``bslam simulate``: the real recorder against the simulated Khepera (pty) and camera."""

from __future__ import annotations

from typing import TYPE_CHECKING

import click

from replay.cli.options import SEED, FiniteFloat
from replay.cli.recording import frame_options, live_options

if TYPE_CHECKING:
    from data_schemas.registry import ImageEncoding


@click.command("simulate")
@click.option(
    "--scenario",
    "scenario_arg",
    required=True,
    help="Scenario JSON file, or a built-in name (paper, paper_omni, coded_3x2).",
)
@click.option("--out", required=True, type=click.Path(dir_okay=False), help="Log to write.")
@click.option("--seed", type=SEED, default=None, help="Replaces the scenario's trajectory.seed.")
@frame_options
@click.option(
    "--turn-noise",
    type=FiniteFloat(min=0),
    default=0.02,
    show_default=True,
    help="Actuation noise: relative std of each turn.",
)
@click.option(
    "--distance-noise",
    type=FiniteFloat(min=0),
    default=0.02,
    show_default=True,
    help="Actuation noise: relative std of each straight distance.",
)
@click.option(
    "--speed",
    type=click.FloatRange(min=0, min_open=True),
    default=None,
    help="Run at FACTOR x real time (1 = real time); default as fast as possible.",
    metavar="FACTOR",
)
@live_options
def simulate(
    scenario_arg: str,
    out: str,
    seed: int | None,
    frame_rate_hz: float,
    encoding: ImageEncoding,  # click.Choice(list(IMAGE_SCHEMA))
    png_level: int,
    turn_noise: float,
    distance_noise: float,
    chunk_compression: str,
    force: bool,
    speed: float | None,
    live: bool,
    spawn: bool,
    connect: str | None,
    save_rrd: str | None,
) -> None:
    """Simulate a session: the same record loop as `bslam record`, in virtual time.

    The robot is a simulated Khepera served on a pseudo-terminal (real serial I/O), the camera
    renders the scenario from the robot's true pose, and `/sim/ground_truth` holds that pose at
    every frame.
    """
    from recorder.record import RecordSettings
    from recorder.sim.scenario import BUILTIN_SCENARIOS, scenario_named
    from recorder.sim.simulate import SimSettings, simulate_to_file
    from replay.cli.recording import live_view, run_recording

    scenario = scenario_named(scenario_arg)
    if seed is not None:
        scenario = scenario.with_seed(seed)
    settings = SimSettings(
        RecordSettings(
            frame_rate_hz=frame_rate_hz,
            encoding=encoding,
            png_level=png_level,
            chunk_compression="" if chunk_compression == "none" else chunk_compression,
        ),
        turn_noise=turn_noise,
        distance_noise=distance_noise,
        speed=speed,
    )
    run_recording(
        out,
        lambda path, progress: simulate_to_file(
            scenario, path, settings=settings, source=scenario_arg, progress=progress
        ),
        total=scenario.trajectory.n_moves,
        force=force,
        inputs=[] if scenario_arg in BUILTIN_SCENARIOS else [scenario_arg],
        live=live_view(live, spawn, connect, save_rrd),
    )
