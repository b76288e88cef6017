"""Bearing extraction speed on one core: profile (column / ring sums) vs connected components,
next to the cost of decoding a logged frame (base64 + PNG) and a yardstick (``cv2.cvtColor``
BGR->HSV of the same frame) measured in the same run.

Run: ``python -m pytest tests/bench/test_bench_bearings.py -s`` (prints fps and ratios).
"""

from __future__ import annotations

import base64
import math
import statistics
import time
from collections.abc import Callable
from functools import cache
from typing import Any

import cv2
import numpy as np
import pytest

from data_schemas.calibration import Calibration, UnwrappedCalibration, default_omni
from data_schemas.session import LandmarkSpec
from pipeline.bearings import BearingExtractor, decode_frame
from recorder.sim.render import Lighting, render_panorama
from recorder.sim.scenario import builtin_scenario

SIZES = [(255, 176), (1920, 960)]
MODELS = ["unwrapped", "omni"]


@pytest.fixture(autouse=True, scope="module")
def _one_core() -> Any:
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    yield
    cv2.setNumThreads(threads)


def _calibration(model: str, size: tuple[int, int]) -> Calibration:
    return UnwrappedCalibration(*size) if model == "unwrapped" else default_omni(*size)


@cache
def _frame(model: str, size: tuple[int, int]) -> np.ndarray:
    world = builtin_scenario("paper").world()
    rng = np.random.default_rng(0)
    frame = render_panorama(
        (0.52, 0.34, 0.4),
        world,
        _calibration(model, size),
        rng,
        bearing_noise_rad=0.0,
        vision_error_rad=math.radians(3.0),
        pixel_noise=3.0,
        lighting=Lighting(),
    )
    return frame.image_bgr


def _median_s(fn: Callable[[], object], min_time_s: float = 0.3) -> float:
    """Median wall time of ``fn`` over repeated calls (at least 7, about ``min_time_s``)."""
    fn()
    times: list[float] = []
    start = time.perf_counter()
    while len(times) < 7 or time.perf_counter() - start < min_time_s:
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def _catalog() -> list[LandmarkSpec]:
    return [LandmarkSpec(lm.name, lm.color) for lm in builtin_scenario("paper").world().landmarks]


@pytest.mark.parametrize("method", ["profile", "components"])
@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
def test_extract_speed(benchmark: Any, size: tuple[int, int], model: str, method: str) -> None:
    image = _frame(model, size)
    extractor = BearingExtractor(_calibration(model, size), _catalog(), method=method)  # type: ignore[arg-type]
    detections = extractor.extract(image)
    assert sum(d.visible for d in detections.values()) >= 3
    yardstick = _median_s(lambda: cv2.cvtColor(image, cv2.COLOR_BGR2HSV))
    benchmark(extractor.extract, image)
    median = benchmark.stats.stats.median
    benchmark.extra_info.update(
        fps=1.0 / median, cvtcolor_s=yardstick, ratio_to_cvtcolor=median / yardstick
    )
    print(
        f"\n{size[0]}x{size[1]} {model:9s} {method:10s} extract {median * 1e6:8.0f} us "
        f"= {1 / median:7.0f} frames/s; {median / yardstick:5.1f}x cvtColor "
        f"({yardstick * 1e6:.0f} us)"
    )


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
def test_batch_speed(benchmark: Any, size: tuple[int, int], model: str) -> None:
    image = _frame(model, size)
    extractor = BearingExtractor(_calibration(model, size), _catalog())
    frames = np.stack([image] * (32 if size[0] < 1000 else 4))
    benchmark(extractor.extract_batch, frames)
    per_frame = benchmark.stats.stats.median / len(frames)
    benchmark.extra_info.update(fps=1.0 / per_frame)
    print(f"\n{size[0]}x{size[1]} {model:9s} batch      {1 / per_frame:7.0f} frames/s")


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
def test_decode_speed(benchmark: Any, size: tuple[int, int], model: str) -> None:
    image = _frame(model, size)
    ok, png = cv2.imencode(".png", image)
    assert ok
    text = base64.b64encode(png.tobytes()).decode()  # as in the JSON CompressedImage message

    def decode() -> np.ndarray:
        return decode_frame(base64.b64decode(text), "png")

    assert np.array_equal(decode(), image)
    yardstick = _median_s(lambda: cv2.cvtColor(image, cv2.COLOR_BGR2HSV))
    benchmark(decode)
    median = benchmark.stats.stats.median
    benchmark.extra_info.update(fps=1.0 / median, ratio_to_cvtcolor=median / yardstick)
    print(
        f"\n{size[0]}x{size[1]} {model:9s} decode (base64+png, {len(text) / 1e3:.0f} kB) "
        f"{median * 1e6:8.0f} us = {1 / median:6.0f} frames/s; {median / yardstick:5.1f}x cvtColor"
    )
