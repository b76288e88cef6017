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


N_CODED = (4, 8, 16, 32)
CODED_SIZES = {"unwrapped": (960, 160), "omni": (480, 480)}


@cache
def _coded_setup(model: str, n: int) -> tuple[np.ndarray, BearingExtractor]:
    """A frame from the middle of a 3 x 2 m arena with ``n`` coded landmarks, and its extractor."""
    from recorder.sim.coded import coded_landmarks
    from recorder.sim.world import Arena, Landmark, SimWorld

    docs = coded_landmarks(3.0, 2.0, n, np.random.default_rng(n))
    landmarks = tuple(
        Landmark(d["name"], d["x"], d["y"], None, bands=tuple(d["bands"])) for d in docs
    )
    world = SimWorld(Arena(3.0, 2.0), landmarks)
    cal = _calibration(model, CODED_SIZES[model])
    xy = min(
        ((x, y) for x in np.linspace(1.2, 1.8, 7) for y in np.linspace(0.8, 1.2, 5)),
        key=lambda p: -np.hypot(*(world.xy_world - p).T).min(),
    )
    frame = render_panorama(
        (*xy, 0.3),
        world,
        cal,
        np.random.default_rng(0),
        bearing_noise_rad=0.0,
        vision_error_rad=math.radians(3.0),
        pixel_noise=2.0,
        lighting=Lighting(),
    )
    catalog = [LandmarkSpec(lm.name, None, bands=lm.bands) for lm in landmarks]
    return frame.image_bgr, BearingExtractor(cal, catalog)


@pytest.mark.parametrize("model", MODELS)
def test_extract_cost_against_the_number_of_coded_landmarks(model: str) -> None:
    """Median extract time with 4, 8, 16, 32 coded landmarks, each alternated with the
    cvtColor yardstick of the same frame (ratios are comparable across runs)."""
    lines = []
    per_n = {}
    for n in N_CODED:
        image, extractor = _coded_setup(model, n)
        seen = sum(d.visible for d in extractor.extract(image).values())
        assert seen >= n // 2
        ours, yard = [], []
        for _ in range(15):
            ours.append(_median_s(lambda ex=extractor, im=image: ex.extract(im), 0.05))
            yard.append(_median_s(lambda im=image: cv2.cvtColor(im, cv2.COLOR_BGR2HSV), 0.02))
        t, y = statistics.median(ours), statistics.median(yard)
        per_n[n] = t / y
        lines.append(
            f"{model} {n:2d} codes ({seen:2d} read): {t * 1e3:6.2f} ms = {t / y:5.1f}x cvtColor, "
            f"{t / n * 1e3:5.2f} ms per landmark"
        )
    print("\n" + "\n".join(lines))
    # the cost per landmark must not grow with the number of landmarks
    assert per_n[32] / 32 <= 1.5 * per_n[4] / 4
