"""``bslam record``: record a session on a real robot and camera."""

from __future__ import annotations

import math
import os
from typing import TYPE_CHECKING

import click

from replay.cli.options import SEED, FiniteFloat
from replay.cli.recording import frame_options, live_options

if TYPE_CHECKING:
    from data_schemas.registry import ImageEncoding


#: The longest straight drive ``--distance`` accepts, metres (a robot in a lab or a field).
MAX_DRIVE_M = 100.0


def _distance_range(ctx: click.Context, param: click.Parameter, text: str) -> tuple[float, float]:
    parts = text.split(",")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise click.BadParameter(f"expected D or MIN,MAX in metres, got {text!r}") from None
    if len(values) == 1:
        values = values * 2
    if len(values) != 2 or not 0 < values[0] <= values[1] <= MAX_DRIVE_M:
        raise click.BadParameter(
            f"expected D or MIN,MAX with 0 < MIN <= MAX <= {MAX_DRIVE_M:g} m, got {text[:40]!r}"
        )
    return values[0], values[1]


@click.command("record")
@click.option("--port", help="Serial port of the robot (/dev/ttyUSB0) or URL.")
@click.option(
    "--no-robot",
    is_flag=True,
    help="No robot: record every frame of --camera (and --odometry) as they come.",
)
@click.option(
    "--odometry",
    type=click.Path(dir_okay=False),
    help="With --no-robot: odometry CSV, as for `bslam import csv` (poses or velocities) "
    "[default: none].",
)
@click.option(
    "--camera",
    "camera_source",
    required=True,
    help="Device index, URL, video, frames_%04d.png, or (--no-robot) a folder of images.",
)
@click.option("--out", required=True, type=click.Path(dir_okay=False), help="Log to write (.mcap).")
@click.option(
    "--calibration",
    required=True,
    type=click.Path(dir_okay=False),
    help="Camera calibration JSON (bslam.Calibration).",
)
@click.option(
    "--landmarks",
    required=True,
    type=click.Path(dir_okay=False),
    help="Landmark file JSON: landmarks, reference, vision_error_deg.",
)
@click.option(
    "--moves",
    type=click.IntRange(min=0),
    default=10,
    show_default=True,
    help="Movements; 0 = until Ctrl-C.",
)
@click.option(
    "--distance",
    default="0.10,0.25",
    show_default=True,
    callback=_distance_range,
    help="Straight distance D or range MIN,MAX, metres.",
)
@click.option(
    "--turn-deg",
    type=FiniteFloat(min=-180.0, max=180.0),
    default=None,
    help="Fixed turn in place before each drive, degrees, counter-clockwise positive "
    "[default: random].",
)
@click.option("--seed", type=SEED, default=None, help="Seed of the random turns and distances.")
@frame_options
@click.option(
    "--baud",
    type=click.IntRange(min=1, max=4_000_000),
    default=9600,
    show_default=True,
    help="Serial baud rate of the robot's running mode (Khepera II: 9600 to 115200).",
)
@click.option(
    "--model", default="khepera2", show_default=True, help="Robot model name (for the log)."
)
@click.option(
    "--mm-per-pulse",
    type=FiniteFloat(min=0, min_open=True),
    default=0.08,
    show_default=True,
    help="Encoder scale.",
)
@click.option(
    "--wheel-base",
    type=FiniteFloat(min=0, min_open=True),
    default=0.053,
    show_default=True,
    help="Wheel base, metres.",
)
@live_options
def record(
    port: str | None,
    no_robot: bool,
    odometry: str | None,
    camera_source: str,
    out: str,
    calibration: str,
    landmarks: str,
    moves: int,
    distance: tuple[float, float],
    turn_deg: float | None,
    seed: int | None,
    frame_rate_hz: float,
    encoding: ImageEncoding,  # click.Choice(list(IMAGE_SCHEMA))
    png_level: int,
    chunk_compression: str,
    force: bool,
    baud: int,
    model: str,
    mm_per_pulse: float,
    wheel_base: float,
    live: bool,
    spawn: bool,
    connect: str | None,
    save_rrd: str | None,
) -> None:
    """Record a session: turn, keyframe, drive while capturing, keyframe; MOVES times.

    With --no-robot instead of --port: every frame of --camera (a video's own frame times, an
    image sequence at --rate, a live camera's capture clock), and the poses of --odometry.

    Ctrl-C (or SIGTERM) stops the motors and finishes the log cleanly (exit 130 / 143).
    """
    from recorder.record import RecordSettings
    from recorder.start import RobotSessionSpec, record_robot_session
    from replay.cli.recording import live_view, run_recording

    view = live_view(live, spawn, connect, save_rrd)
    if no_robot == (port is not None):
        raise click.UsageError("give --port (a robot) or --no-robot (a camera source alone)")
    if odometry is not None and not no_robot:
        raise click.UsageError("--odometry is for --no-robot (a robot's odometry is recorded)")
    if no_robot:
        from pathlib import Path

        from replay.importers.camera_only import CameraOnlySpec, record_camera_only

        only = CameraOnlySpec(
            camera_source=camera_source,
            calibration_file=Path(calibration),
            landmark_file=Path(landmarks),
            odometry_file=None if odometry is None else Path(odometry),
            rate_hz=frame_rate_hz,
            encoding=encoding,
            png_level=png_level,
            chunk_compression="" if chunk_compression == "none" else chunk_compression,
        )
        inputs = [calibration, landmarks, *([odometry] if odometry else [])]
        run_recording(
            out,
            lambda path, progress: record_camera_only(path, only, progress=progress),
            total=None,
            force=force,
            inputs=[*inputs, *([camera_source] if os.path.isfile(camera_source) else [])],
            live=view,
        )
        return
    assert port is not None

    spec = RobotSessionSpec(
        port=port,
        camera_source=camera_source,
        calibration_file=calibration,
        landmark_file=landmarks,
        moves=moves or None,
        distance_m=distance,
        turn_rad=None if turn_deg is None else math.radians(turn_deg),
        seed=seed,
        robot={
            "model": model,
            "baudrate": baud,
            "mm_per_pulse": mm_per_pulse,
            "wheel_base_m": wheel_base,
        },
        settings=RecordSettings(
            frame_rate_hz=frame_rate_hz,
            encoding=encoding,
            png_level=png_level,
            chunk_compression="" if chunk_compression == "none" else chunk_compression,
        ),
    )
    run_recording(
        out,
        lambda path, progress: record_robot_session(path, spec, progress=progress),
        total=moves or None,
        force=force,
        inputs=[calibration, landmarks],
        live=view,
    )
