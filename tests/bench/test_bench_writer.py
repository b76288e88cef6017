"""Recorder write throughput: frame encode (PNG, lossless) + validate + MCAP write, one core.

Goals (issue 2): >= 1,000 frames/s at 176x255 and >= 30 frames/s at 1920x960. Each case also
measures a yardstick in the same run: plain ``cv2.imencode`` with the same parameters, so the
ratio shows what the recorder adds on top of the PNG encoder. Run:
``python -m pytest tests/bench/test_bench_writer.py --benchmark-columns=median``.
"""

from __future__ import annotations

import io
import math
import time

import cv2
import numpy as np
import pytest

from data_schemas.calibration import UnwrappedCalibration
from data_schemas.session import LandmarkSpec
from recorder.clock import SystemClock
from recorder.frames import encode_png, frame_message, png_params
from recorder.session import build_session_doc
from recorder.timebase import EpochClock
from recorder.writer import LogWriter

SIZES = {"176x255": (176, 255), "1920x960": (960, 1920)}


def _panorama(height: int, width: int) -> np.ndarray:
    """A smooth scene with sensor noise (what a camera delivers: not compressible for free)."""
    rng = np.random.default_rng(0)
    y, x = np.mgrid[0:height, 0:width]
    image = np.stack([x * 255 // width, y * 255 // height, (x + y) % 256], -1).astype(np.uint8)
    image = cv2.GaussianBlur(image, (5, 5), 0)
    noise = rng.integers(-3, 4, image.shape)
    return np.clip(image.astype(np.int16) + noise, 0, 255).astype(np.uint8)


def _doc(height: int, width: int) -> dict[str, object]:
    return build_session_doc(
        created_unix_ns=time.time_ns(),
        robot={"model": "bench", "port": "-", "baudrate": 1, "mm_per_pulse": 1, "wheel_base_m": 1},
        camera_source="bench",
        calibration=UnwrappedCalibration(width, height),
        frame_rate_hz=30.0,
        encoding="png",
        landmarks=[LandmarkSpec("A", "red"), LandmarkSpec("B", "blue")],
        reference=("A", "B"),
        vision_error_rad=math.radians(3),
    )


@pytest.fixture(autouse=True)
def one_core() -> None:
    cv2.setNumThreads(1)


@pytest.mark.parametrize("level", [0, 1])
@pytest.mark.parametrize("size", list(SIZES))
def test_bench_record_frames(benchmark, size: str, level: int) -> None:  # type: ignore[no-untyped-def]
    height, width = SIZES[size]
    image = _panorama(height, width)
    params = png_params(level)
    clock = EpochClock(SystemClock())
    n = 200 if height < 500 else 6

    def yardstick() -> float:
        t0 = time.perf_counter()
        for _ in range(n):
            encode_png(image, params)
        return (time.perf_counter() - t0) / n

    def record() -> None:
        out = io.BytesIO()
        with LogWriter(out, _doc(height, width), clock=clock, fsync=False) as log:
            for _ in range(n):
                log.write(
                    "/camera/panorama",
                    frame_message(image, clock.monotonic_ns(), encoding="png", params=params),
                )

    benchmark.pedantic(record, rounds=5, iterations=1)
    per_frame_s = benchmark.stats.stats.median / n
    encode_s = float(np.median([yardstick() for _ in range(3)]))
    png = encode_png(image, params)
    decoded = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    assert np.array_equal(decoded, image)  # lossless
    benchmark.extra_info.update(
        frames_per_s=round(1 / per_frame_s, 1),
        imencode_frames_per_s=round(1 / encode_s, 1),
        ratio_to_imencode=round(per_frame_s / encode_s, 2),
        png_bytes_per_raw=round(len(png) / image.nbytes, 3),
    )
    print(
        f"\n{size} level {level}: recorder {1 / per_frame_s:.0f} frames/s, "
        f"imencode alone {1 / encode_s:.0f} frames/s (recorder/imencode time "
        f"{per_frame_s / encode_s:.2f}x), PNG {len(png) / image.nbytes:.2f} of raw"
    )
