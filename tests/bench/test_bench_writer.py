"""Recorder write throughput: frame -> message -> validated MCAP record in a file, one core.

Goals (issue 2): >= 1,000 frames/s at 176x255 and >= 30 frames/s at 1920x960, lossless. Cases:
PNG level 0 (stored), PNG level 1 (the default) and raw ``bgr8``, at both sizes, written the
way ``bslam record`` writes (a file, 4 MiB / 0.5 s chunks, ``fsync``), in ``/dev/shm`` when
there is one: this measures the recorder's CPU cost, not the disk (the kernel throttles a
process that dirties pages faster than the disk takes them, whoever made them dirty). Two
yardsticks are measured before each round, so that the ratios mean something on a shared,
loaded machine:

* ``imencode``: OpenCV's fastest PNG encoder (level 1, SUB filter, Huffman only; what the
  recorder used before) on the same frame: a fixed reference across versions;
* ``floor``: the case's own frame encoding (our PNG, or nothing for bgr8), base64, and one
  ``write`` of those bytes to a file: the least any JSON-in-MCAP recorder must do.

Run: ``python -m pytest tests/bench/test_bench_writer.py -s --benchmark-columns=median``.
"""

from __future__ import annotations

import math
import os
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import numpy as np
import pybase64
import pytest

from data_schemas.calibration import UnwrappedCalibration
from data_schemas.mcap.writer import LogWriter
from data_schemas.registry import IMAGE_SCHEMA, ImageEncoding
from data_schemas.session import LandmarkSpec
from recorder.clock import SystemClock
from recorder.frames import frame_message
from recorder.png import encode_png
from recorder.session import build_session_doc
from recorder.timebase import EpochClock

SIZES = {"176x255": (176, 255), "1920x960": (960, 1920)}
CASES = {"png0": ("png", 0), "png1": ("png", 1), "bgr8": ("bgr8", 0)}
OPENCV_FAST_PNG = [
    cv2.IMWRITE_PNG_COMPRESSION,
    1,
    cv2.IMWRITE_PNG_FILTER,
    cv2.IMWRITE_PNG_FILTER_SUB,
    cv2.IMWRITE_PNG_STRATEGY,
    cv2.IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY,
]


def _panorama(height: int, width: int) -> np.ndarray:
    """A smooth scene with sensor noise (what a camera delivers: not compressible for free)."""
    rng = np.random.default_rng(0)
    y, x = np.mgrid[0:height, 0:width]
    image = np.stack([x * 255 // width, y * 255 // height, (x + y) % 256], -1).astype(np.uint8)
    image = cv2.GaussianBlur(image, (5, 5), 0)
    noise = rng.integers(-3, 4, image.shape)
    return np.clip(image.astype(np.int16) + noise, 0, 255).astype(np.uint8)


def _doc(height: int, width: int, encoding: ImageEncoding) -> dict[str, object]:
    return build_session_doc(
        created_unix_ns=time.time_ns(),
        robot={"model": "bench", "port": "-", "baudrate": 1, "mm_per_pulse": 1, "wheel_base_m": 1},
        camera_source="bench",
        calibration=UnwrappedCalibration(width, height),
        frame_rate_hz=30.0,
        encoding=encoding,
        landmarks=[LandmarkSpec("A", "red"), LandmarkSpec("B", "blue")],
        reference=("A", "B"),
        vision_error_rad=math.radians(3),
    )


def _per_frame_s(fn: Callable[[], object], n: int) -> float:
    """Mean time of ``n`` calls, seconds."""
    t0 = time.perf_counter()
    for _ in range(n):
        fn()
    return (time.perf_counter() - t0) / n


@pytest.fixture(autouse=True)
def one_core() -> None:
    cv2.setNumThreads(1)


@pytest.fixture
def out_dir(tmp_path: Path) -> Iterator[Path]:
    """A folder in memory (``/dev/shm``) if the system has one, else ``tmp_path``."""
    if not os.path.isdir("/dev/shm"):
        yield tmp_path
        return
    with tempfile.TemporaryDirectory(dir="/dev/shm") as folder:
        yield Path(folder)


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize("size", list(SIZES))
def test_bench_record_frames(benchmark, out_dir: Path, size: str, case: str) -> None:  # type: ignore[no-untyped-def]
    height, width = SIZES[size]
    encoding, level = CASES[case]
    image = _panorama(height, width)
    clock = EpochClock(SystemClock())
    n = 500 if height < 500 else 30
    doc = _doc(height, width, encoding)  # type: ignore[arg-type]
    path = out_dir / "bench.mcap"

    def record() -> None:
        with LogWriter(path, doc, clock=clock) as log:
            for _ in range(n):
                msg = frame_message(image, clock.monotonic_ns(), encoding=encoding, png_level=level)  # type: ignore[arg-type]
                log.write("/camera/panorama", msg, schema=IMAGE_SCHEMA[encoding])

    def encode() -> bytes:
        return encode_png(image, level) if encoding == "png" else image.tobytes()

    floor_times: list[float] = []
    imencode_times: list[float] = []

    def yardsticks() -> None:  # run before each round (not timed by pytest-benchmark)
        with (out_dir / "floor.bin").open("wb") as sink:
            floor_times.append(_per_frame_s(lambda: sink.write(pybase64.b64encode(encode())), n))
        imencode = lambda: cv2.imencode(".png", image, OPENCV_FAST_PNG)  # noqa: E731
        imencode_times.append(_per_frame_s(imencode, n))

    benchmark.pedantic(record, setup=yardsticks, rounds=5, iterations=1)
    per_frame_s = benchmark.stats.stats.median / n
    floor_s = float(np.median(floor_times))
    imencode_s = float(np.median(imencode_times))

    if encoding == "png":  # lossless, read back by OpenCV
        decoded = cv2.imdecode(np.frombuffer(encode(), np.uint8), cv2.IMREAD_UNCHANGED)
        assert np.array_equal(decoded, image)
    benchmark.extra_info.update(
        frames_per_s=round(1 / per_frame_s, 1),
        floor_frames_per_s=round(1 / floor_s, 1),
        imencode_frames_per_s=round(1 / imencode_s, 1),
        ratio_to_floor=round(per_frame_s / floor_s, 2),
        ratio_to_imencode=round(per_frame_s / imencode_s, 2),
        bytes_per_raw=round(len(encode()) / image.nbytes, 3),
    )
    print(
        f"\n{size} {case}: recorder {1 / per_frame_s:.0f} frames/s; time per frame "
        f"{per_frame_s / floor_s:.2f}x floor ({1 / floor_s:.0f}/s), "
        f"{per_frame_s / imencode_s:.2f}x imencode ({1 / imencode_s:.0f}/s); "
        f"stored {len(encode()) / image.nbytes:.2f} of raw"
    )
