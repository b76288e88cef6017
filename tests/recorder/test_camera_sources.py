"""OpenCVCamera over real image sequences and video files; a stand-in capture for a device."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from data_schemas.calibration import UnwrappedCalibration
from data_schemas.errors import CameraError, ImageError
from recorder.camera import CameraDisconnected, CameraEndOfStream, OpenCVCamera, source_kind


def _sequence(tmp_path: Path, n: int, shape: tuple[int, int] = (16, 40)) -> list[np.ndarray]:
    rng = np.random.default_rng(3)
    frames = [rng.integers(0, 256, (*shape, 3), dtype=np.uint8) for _ in range(n)]
    for i, frame in enumerate(frames):
        assert cv2.imwrite(str(tmp_path / f"frames_{i:04d}.png"), frame)
    return frames


def test_source_kinds() -> None:
    assert source_kind("0") == "device"
    assert source_kind("rtsp://cam/1") == "url"
    assert source_kind("x/frames_%04d.png") == "sequence"
    assert source_kind("run.avi") == "file"


def test_image_sequence_reads_every_frame_then_ends(tmp_path: Path) -> None:
    frames = _sequence(tmp_path, 4)
    camera = OpenCVCamera(str(tmp_path / "frames_%04d.png"), UnwrappedCalibration(40, 16))
    try:
        for expected in frames:
            got = camera.read()
            assert got.dtype == np.uint8 and got.shape == (16, 40, 3)
            np.testing.assert_array_equal(got, expected)  # PNG: lossless, BGR order kept
        with pytest.raises(CameraEndOfStream, match="ended after 4 frames"):
            camera.read()
    finally:
        camera.close()
        camera.close()


def test_frame_size_must_match_calibration(tmp_path: Path) -> None:
    _sequence(tmp_path, 1)
    camera = OpenCVCamera(str(tmp_path / "frames_%04d.png"), UnwrappedCalibration(255, 176))
    with pytest.raises(ImageError, match=r"delivers 40x16 frames but the calibration is for 255x"):
        camera.read()
    camera.close()


@pytest.mark.parametrize(
    ("source", "hint"),
    [
        ("{tmp}/nothing_%04d.png", "check the pattern"),
        ("{tmp}/missing.avi", "no such file"),
        ("{tmp}/not_a_video.avi", "OpenCV can decode"),
    ],
)
def test_camera_not_opening(tmp_path: Path, source: str, hint: str) -> None:
    (tmp_path / "not_a_video.avi").write_text("garbage")
    path = source.format(tmp=tmp_path)
    with pytest.raises(CameraError, match=rf"^cannot open camera {path}: .*{hint}"):
        OpenCVCamera(path, UnwrappedCalibration(40, 16))


def test_video_file_end_of_stream(tmp_path: Path) -> None:
    path = tmp_path / "clip.avi"
    out = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (40, 16))
    if not out.isOpened():
        pytest.skip("this OpenCV build cannot write MJPG video")
    for _ in range(3):
        out.write(np.full((16, 40, 3), 128, np.uint8))
    out.release()
    camera = OpenCVCamera(str(path), UnwrappedCalibration(40, 16))
    n = 0
    with pytest.raises(CameraEndOfStream):
        while True:
            camera.read()
            n += 1
    assert n == 3
    camera.close()


class _UnpluggedDevice:
    """Stand-in for a physical camera that delivers ``frames`` frames, then nothing."""

    def __init__(self, index: Any, frames: int = 2) -> None:
        assert index == 0  # a device source is opened by its integer index
        self.left = frames
        self.reads = 0
        self.released = False

    def isOpened(self) -> bool:
        return True

    def read(self) -> tuple[bool, np.ndarray | None]:
        self.reads += 1
        if self.left == 0:
            return False, None
        self.left -= 1
        return True, np.zeros((16, 40), np.uint8)  # grey frames are converted to BGR

    def release(self) -> None:
        self.released = True


def test_live_device_unplugged_is_a_distinct_error() -> None:
    device = _UnpluggedDevice(0)
    camera = OpenCVCamera("0", UnwrappedCalibration(40, 16), capture_factory=lambda i: device)
    assert camera.read().shape == (16, 40, 3)
    camera.read()
    with pytest.raises(CameraDisconnected, match=r"camera 0 stopped delivering frames after 2"):
        camera.read()
    assert device.reads == 2 + 3  # a live source gets a few tries before it counts as gone
    assert not isinstance(CameraDisconnected("x"), CameraEndOfStream)
    camera.close()
    assert device.released


def test_device_not_opening() -> None:
    class Closed(_UnpluggedDevice):
        def isOpened(self) -> bool:
            return False

    with pytest.raises(CameraError, match=r"^cannot open camera 0: check that it is plugged in"):
        OpenCVCamera("0", UnwrappedCalibration(40, 16), capture_factory=Closed)
