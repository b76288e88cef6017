"""Hand-made bearing-slam logs for replay tests (bad inputs, edge cases, fast unit runs).

Frames are unwrapped panoramas painted with a vertical bar per landmark at its true bearing,
written with the real :class:`~data_schemas.mcap.writer.LogWriter`. The end-to-end tests use the
real simulator (``bslam simulate``); this factory makes the odd logs it would never write.
"""

from __future__ import annotations

import base64
import math
from collections.abc import Callable, Collection
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from data_schemas.calibration import UnwrappedCalibration
from data_schemas.colors import NOMINAL_BGR
from data_schemas.mcap.writer import LogWriter
from data_schemas.paper_arena import PAPER_ARENA_M, PAPER_LANDMARKS_M, PAPER_REFERENCE
from data_schemas.session import LandmarkSpec
from data_schemas.stamps import stamp_from_ns
from recorder.clock import VirtualClock
from recorder.session import build_session_doc
from recorder.timebase import EpochClock

COLORS = {"L1": "red", "L2": "green", "L3": "blue", "L4": "yellow"}
#: The paper's landmarks: name -> (x, y, colour), m, world frame.
LANDMARKS = {n: (*PAPER_LANDMARKS_M[n], c) for n, c in COLORS.items()}
WIDTH, HEIGHT = 360, 40


def scenario() -> dict[str, Any]:
    return {
        "arena": {"width": PAPER_ARENA_M[0], "height": PAPER_ARENA_M[1]},
        "landmarks": [
            {"name": n, "x": x, "y": y, "color": c} for n, (x, y, c) in LANDMARKS.items()
        ],
        "reference": list(PAPER_REFERENCE),
        "camera": {"model": "unwrapped", "width": WIDTH, "height": HEIGHT},
        "vision_error_deg": 3.0,
        "trajectory": {"start": [0.52, 0.34], "moves": 3},
    }


def session_doc() -> dict[str, Any]:
    return build_session_doc(
        created_unix_ns=1_700_000_000 * 10**9,
        robot={
            "model": "sim",
            "port": "sim",
            "baudrate": 9600,
            "mm_per_pulse": 0.08,
            "wheel_base_m": 0.053,
        },
        camera_source="sim",
        calibration=UnwrappedCalibration(WIDTH, HEIGHT),
        frame_rate_hz=5.0,
        encoding="png",
        landmarks=[LandmarkSpec(n, c) for n, (_, _, c) in LANDMARKS.items()],
        reference=("L1", "L2"),
        vision_error_rad=math.radians(3.0),
        scenario=scenario(),
    )


def render(x: float, y: float, heading: float, hidden: tuple[str, ...] = ()) -> np.ndarray:
    """An unwrapped panorama seen from pose (x, y, heading) in the world frame."""
    cal = UnwrappedCalibration(WIDTH, HEIGHT)
    image = np.full((HEIGHT, WIDTH, 3), 60, np.uint8)
    for name, (lx, ly, color) in LANDMARKS.items():
        if name in hidden:
            continue
        bearing = math.atan2(ly - y, lx - x) - heading
        u = float(cal.column_of_bearing(bearing))
        for du in (-2, -1, 0, 1, 2):
            image[5:-5, math.floor(u + du) % WIDTH] = NOMINAL_BGR[color]
    return image


def frame_msg(t_ns: int, image: np.ndarray) -> dict[str, Any]:
    ok, png = cv2.imencode(".png", image)
    assert ok
    return {
        "timestamp": stamp_from_ns(t_ns),
        "frame_id": "panorama",
        "format": "png",
        "data": base64.b64encode(png.tobytes()).decode(),
    }


#: Straight movements: (start x, y, heading) then drive distance.
MOVES = [((0.52, 0.34, 0.3), 0.2), ((0.70, 0.40, 2.6), 0.2), ((0.52, 0.48, -1.9), 0.15)]


def write_log(
    path: Path,
    *,
    moves: list[tuple[tuple[float, float, float], float]] = MOVES,
    hidden: Callable[[int, str], tuple[str, ...]] = lambda i, phase: (),
    doc: dict[str, Any] | None = None,
    extra: Callable[[LogWriter], None] | None = None,
    finish: bool = True,
    between: int = 1,
    instant: Collection[int] = (),
) -> Path:
    """Write a log of ``moves`` (keyframes at both ends, ``between`` frames in between).

    A movement in ``instant`` starts at the time stamp its predecessor ended (a turn too short
    to take a clock tick): two frames then share one time stamp, each the keyframe of one."""
    clock = VirtualClock()
    epoch = EpochClock(clock)
    writer = LogWriter(path, session_doc() if doc is None else doc, clock=epoch, fsync=False)
    if extra is not None:
        extra(writer)
    for index, ((x, y, h), dist) in enumerate(moves):
        ends = [(x, y), (x + dist * math.cos(h), y + dist * math.sin(h))]
        for k, phase in enumerate(("start", "end")):
            px, py = ends[k]
            if phase == "end":
                for j in range(between):
                    clock.advance_ns(100_000_000)
                    f = (j + 1) / (between + 1)
                    mx, my = x + f * (px - x), y + f * (py - y)
                    writer.write(
                        "/camera/panorama", frame_msg(epoch.monotonic_ns(), render(mx, my, h))
                    )
            if not (phase == "start" and index in instant):
                clock.advance_ns(100_000_000)
            t = epoch.monotonic_ns()
            writer.write(
                "/sim/ground_truth", {"timestamp": stamp_from_ns(t), "x": px, "y": py, "heading": h}
            )
            writer.write("/camera/panorama", frame_msg(t, render(px, py, h, hidden(index, phase))))
            writer.write(
                "/robot/movement",
                {
                    "timestamp": stamp_from_ns(t),
                    "index": index,
                    "phase": phase,
                    "keyframe_timestamp": stamp_from_ns(t),
                    "turn_rad": 0.0,
                    "distance_m": dist,
                },
            )
    if finish:
        writer.finish()
    else:  # what a killed recorder leaves: chunks on disk, no footer, its lock released
        writer.flush()
        writer._stream.close()
    return path
