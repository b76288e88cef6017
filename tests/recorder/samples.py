"""Test data for recorder tests: a valid session document and one message for every topic."""

from __future__ import annotations

import base64
import math
from typing import Any

import cv2
import numpy as np

from data_schemas.calibration import UnwrappedCalibration
from data_schemas.session import LandmarkSpec
from data_schemas.stamps import stamp_from_ns
from recorder.session import build_session_doc

T0_NS = 1_700_000_000_000_000_000


def make_session_doc() -> dict[str, Any]:
    """A real-robot session document for a 32x16 unwrapped camera (a fixed session id)."""
    doc = build_session_doc(
        created_unix_ns=T0_NS,
        robot={
            "model": "khepera",
            "port": "/dev/null",
            "baudrate": 9600,
            "mm_per_pulse": 0.08,
            "wheel_base_m": 0.053,
        },
        camera_source="0",
        calibration=UnwrappedCalibration(32, 16),
        frame_rate_hz=5.0,
        encoding="png",
        landmarks=[LandmarkSpec("L1", "red"), LandmarkSpec("L2", "green")],
        reference=("L1", "L2"),
        vision_error_rad=math.radians(3.0),
    )
    doc["session_id"] = "5e55" * 8
    return doc


def sample_messages(t_ns: int, rng: np.random.Generator) -> dict[str, dict[str, Any]]:
    """One valid message per registered topic, time stamped ``t_ns``."""
    stamp = stamp_from_ns(t_ns)
    image = rng.integers(0, 256, (16, 32, 3), dtype=np.uint8)
    ok, png = cv2.imencode(".png", image)
    assert ok
    return {
        "/camera/panorama": {
            "timestamp": stamp,
            "frame_id": "panorama",
            "format": "png",
            "data": base64.b64encode(png.tobytes()).decode(),
        },
        "/robot/command": {
            "timestamp": stamp,
            "request": "D,0,0",
            "reply": "d",
            "outcome": "ok",
            "latency_ns": 1000,
            "attempt": 1,
        },
        "/robot/odometry": {"timestamp": stamp, "left_pulses": 10, "right_pulses": -4},
        "/robot/odometry_pose": {"timestamp": stamp, "x_m": 1.5, "y_m": -0.25, "theta_rad": 0.5},
        "/sensor/bearings": {
            "timestamp": stamp,
            "source": "beacon sensor",
            "bearings": [
                {"landmark": "L1", "bearing_rad": 0.25},
                {"landmark": "L2", "bearing_rad": -2.0, "std_rad": 0.01},
            ],
        },
        "/robot/movement": {
            "timestamp": stamp,
            "index": 0,
            "phase": "start",
            "keyframe_timestamp": stamp,
            "turn_rad": 0.3,
            "distance_m": 0.1,
        },
        "/log": {
            "timestamp": stamp,
            "level": 2,
            "message": "hello",
            "name": "recorder",
            "file": "",
            "line": 0,
        },
        "/sim/ground_truth": {"timestamp": stamp, "x": 0.1, "y": 0.2, "heading": -1.0},
        "/truth/robot_pose": {"timestamp": stamp, "x": 1.5, "y": -0.5, "heading": 0.25},
    }
