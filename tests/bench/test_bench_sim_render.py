"""Benchmark: simulated panorama rendering, per camera model and image size.

Run: ``python -m pytest tests/bench/test_bench_sim_render.py``. Each group pairs the renderer
with a yardstick measured in the same run on the same image size: OpenCV's BGR -> HSV
conversion (the first thing colour thresholding does with a frame). Compare the medians.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from pytest_benchmark.fixture import BenchmarkFixture

from data_schemas.calibration import Calibration, UnwrappedCalibration, default_omni
from recorder.sim.render import Lighting, render_panorama
from recorder.sim.scenario import builtin_scenario

CASES: dict[str, Calibration] = {
    "unwrapped 255x176": UnwrappedCalibration(255, 176),
    "omni 320x320": default_omni(320, 320),
    "unwrapped 1920x960": UnwrappedCalibration(1920, 960),
    "omni 960x960": default_omni(960, 960),
}


@pytest.mark.parametrize("name", CASES)
def test_render(benchmark: BenchmarkFixture, name: str) -> None:
    benchmark.group = name
    cal = CASES[name]
    world = builtin_scenario("paper").world()
    rng = np.random.default_rng(0)
    render_panorama((0.5, 0.3, 0.2), world, cal, rng, bearing_noise_rad=0.0, vision_error_rad=0.05)

    def run() -> None:
        render_panorama(
            (0.5, 0.3, 0.2),
            world,
            cal,
            rng,
            bearing_noise_rad=math.radians(1.0),
            vision_error_rad=math.radians(3.0),
            lighting=Lighting(),
        )

    benchmark(run)


@pytest.mark.parametrize("name", CASES)
def test_yardstick_bgr_to_hsv(benchmark: BenchmarkFixture, name: str) -> None:
    benchmark.group = name
    cal = CASES[name]
    image = np.random.default_rng(0).integers(0, 256, (cal.height, cal.width, 3), np.uint8)
    benchmark(cv2.cvtColor, image, cv2.COLOR_BGR2HSV)
