"""The simulated panoramic camera: renders the world from the robot's true pose on each read.

:class:`SimCamera` has the recorder's camera interface (``read()`` -> BGR frame,
``calibration``, ``close()``) plus ``last_frame`` / ``last_truth`` (what the renderer drew on
the last read: true and noisy bearings, visibility) for ground truth and tests.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from data_schemas.calibration import Calibration
from data_schemas.errors import CameraError
from recorder.sim.render import LandmarkTruth, Lighting, RenderedFrame, render_panorama
from recorder.sim.scenario import Scenario
from recorder.sim.world import Pose, SimWorld


class SimCamera:
    """A camera that renders :class:`~recorder.sim.world.SimWorld` at the robot's true pose.

    Parameters
    ----------
    world : SimWorld
    calibration : Calibration
        Camera model and image size.
    true_pose : callable () -> (x, y, heading)
        The robot's current true pose, world frame (m, m, rad).
    rng : numpy.random.Generator
        Source of bearing, lighting and pixel noise.
    bearing_noise_rad, vision_error_rad : float
        Bearing noise std and its truncation bound eps (rad).
    pixel_noise : float
        Pixel noise std, grey levels.
    lighting : Lighting or None
        Lighting variation (None = constant).
    """

    def __init__(
        self,
        world: SimWorld,
        calibration: Calibration,
        true_pose: Callable[[], Pose],
        rng: np.random.Generator,
        *,
        bearing_noise_rad: float,
        vision_error_rad: float,
        pixel_noise: float = 2.0,
        lighting: Lighting | None = None,
    ) -> None:
        self.world = world
        self.calibration = calibration
        self._true_pose = true_pose
        self._rng = rng
        self.bearing_noise_rad = bearing_noise_rad
        self.vision_error_rad = vision_error_rad
        self.pixel_noise = pixel_noise
        self.lighting = lighting
        self.last_frame: RenderedFrame | None = None
        self.last_pose_world: Pose | None = None
        self._closed = False

    @classmethod
    def from_scenario(
        cls, scenario: Scenario, true_pose: Callable[[], Pose], rng: np.random.Generator
    ) -> SimCamera:
        """The camera a scenario describes (model, size, noise, lighting)."""
        return cls(
            scenario.world(),
            scenario.calibration(),
            true_pose,
            rng,
            bearing_noise_rad=scenario.camera.bearing_noise_rad,
            vision_error_rad=scenario.vision_error_rad,
            pixel_noise=scenario.camera.pixel_noise,
            lighting=Lighting() if scenario.camera.lighting else None,
        )

    @property
    def last_truth(self) -> tuple[LandmarkTruth, ...] | None:
        """Per-landmark truth of the last frame read (None before the first read)."""
        return None if self.last_frame is None else self.last_frame.truth

    def read(self) -> NDArray[np.uint8]:
        """Render and return the frame at the current true pose, BGR uint8 (H, W, 3)."""
        if self._closed:
            raise CameraError("simulated camera is closed")
        pose = self._true_pose()
        frame = render_panorama(
            pose,
            self.world,
            self.calibration,
            self._rng,
            bearing_noise_rad=self.bearing_noise_rad,
            vision_error_rad=self.vision_error_rad,
            pixel_noise=self.pixel_noise,
            lighting=self.lighting,
        )
        self.last_frame = frame
        self.last_pose_world = pose
        return frame.image_bgr

    def close(self) -> None:
        """Stop the camera (idempotent); later reads raise CameraError."""
        self._closed = True
