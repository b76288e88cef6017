"""World geometry: bearings, ranges, angular widths, occlusion; and the simulated camera."""

from __future__ import annotations

import math

import numpy as np
import pytest

from data_schemas.errors import CameraError
from recorder.sim.camera import SimCamera
from recorder.sim.scenario import builtin_scenario
from recorder.sim.world import Arena, Landmark, Pose, SimWorld

ARENA = Arena(1.0, 1.0)


def test_bearings_and_ranges_in_the_robot_frame() -> None:
    world = SimWorld(
        ARENA,
        (
            Landmark("ahead", 0.8, 0.5, "red"),
            Landmark("left", 0.5, 0.9, "green"),
            Landmark("behind", 0.1, 0.5, "blue"),
        ),
    )
    pose = (0.5, 0.5, 0.0)
    assert world.bearings_rad(pose) == pytest.approx([0.0, math.pi / 2, -math.pi])
    assert world.ranges_m(pose) == pytest.approx([0.3, 0.4, 0.4])
    # turning the robot left by 90 degrees turns every bearing right by 90 degrees
    turned = world.bearings_rad((0.5, 0.5, math.pi / 2))
    assert turned == pytest.approx([-math.pi / 2, 0.0, math.pi / 2])
    assert world.half_widths_rad(pose) == pytest.approx(np.arcsin(0.01 / np.array([0.3, 0.4, 0.4])))
    assert world.names == ("ahead", "left", "behind")


def test_occlusion_fractions() -> None:
    near = Landmark("near", 0.5, 0.5, "red", radius_m=0.02)
    far = Landmark("far", 0.9, 0.5, "green", radius_m=0.02)
    world = SimWorld(ARENA, (near, far))
    assert world.occluded_fractions((0.1, 0.5, 0.0)) == pytest.approx([0.0, 1.0])
    # 4 cm sideways: the near cylinder hides about half of the far one
    pose: Pose = (0.1, 0.54, 0.0)
    fractions = world.occluded_fractions(pose)
    b = world.bearings_rad(pose)
    h = world.half_widths_rad(pose)
    lo = max(b[0] - h[0], b[1] - h[1])
    hi = min(b[0] + h[0], b[1] + h[1])
    assert fractions[0] == 0.0
    assert fractions[1] == pytest.approx(max(hi - lo, 0.0) / (2 * h[1]))
    assert fractions[1] == pytest.approx(0.5, abs=0.05)
    # far apart: nothing hidden
    assert world.occluded_fractions((0.5, 0.1, 0.0)) == pytest.approx([0.0, 0.0])


def test_move_problem_names_the_reason() -> None:
    world = SimWorld(ARENA, (Landmark("L", 0.5, 0.8, "red"),))
    kw = {"robot_radius_m": 0.03, "clearance_m": 0.04}
    assert world.move_problem((0.5, 0.2, 0.0), 0.0, 0.3, **kw) is None
    wall = world.move_problem((0.5, 0.2, 0.0), 0.0, 0.45, **kw)
    assert wall is not None and "wall" in wall
    hit = world.move_problem((0.5, 0.2, 0.0), math.pi / 2, 0.55, **kw)
    assert hit is not None and "landmark L" in hit
    # already too close: moving away is fine, moving closer is not
    assert world.move_problem((0.5, 0.72, 0.0), -math.pi / 2, 0.2, **kw) is None
    assert world.move_problem((0.5, 0.72, 0.0), math.pi / 2, 0.05, **kw) is not None


def test_sim_camera_renders_at_the_true_pose() -> None:
    scenario = builtin_scenario("paper")
    pose: list[Pose] = [(0.52, 0.34, 0.0)]
    camera = SimCamera.from_scenario(scenario, lambda: pose[0], np.random.default_rng(0))
    assert camera.last_truth is None
    image = camera.read()
    assert image.shape == (176, 255, 3) and image.dtype == np.uint8
    assert camera.calibration == scenario.calibration()
    truth = camera.last_truth
    assert truth is not None and [t.name for t in truth] == ["L1", "L2", "L3", "L4"]
    expected = scenario.world().bearings_rad(pose[0])
    assert [t.bearing_true_rad for t in truth] == pytest.approx(expected)
    for t in truth:
        assert abs(t.bearing_drawn_rad - t.bearing_true_rad) <= scenario.vision_error_rad
    pose[0] = (0.3, 0.3, 1.0)
    camera.read()
    assert camera.last_pose_world == (0.3, 0.3, 1.0)
    assert camera.last_truth is not None
    moved = [t.bearing_true_rad for t in camera.last_truth]
    assert moved == pytest.approx(scenario.world().bearings_rad(pose[0]))
    camera.close()
    camera.close()
    with pytest.raises(CameraError):
        camera.read()
