"""Camera sources: the :class:`Camera` interface and :class:`OpenCVCamera` over cv2.VideoCapture.

A source string is read as:

* digits (``"0"``): a device index (``/dev/video0``), a *live* source;
* ``scheme://...`` (``rtsp://``, ``http://``): a network stream, live;
* a pattern with ``%`` (``frames_%04d.png``): an image sequence, finite;
* anything else: a video file, finite.

A finite source that runs out raises :class:`CameraEndOfStream`; a live source that stops
delivering (unplugged, network gone) raises :class:`CameraDisconnected`. Frames are BGR uint8
``(H, W, 3)`` and must have the calibration's size.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any, Literal, Protocol

import cv2
import numpy as np
from numpy.typing import NDArray

from data_schemas.calibration import Calibration
from data_schemas.errors import CameraError, ImageError

SourceKind = Literal["device", "url", "sequence", "file"]

#: Consecutive failed reads before a live source counts as gone.
LIVE_READ_ATTEMPTS = 3


class CameraEndOfStream(CameraError):
    """A finite source (video file, image sequence) has no more frames."""


class CameraDisconnected(CameraError):
    """A live source (device, network stream) stopped delivering frames."""


class Camera(Protocol):
    """A panoramic camera: frames plus the calibration that maps them to bearings."""

    @property
    def calibration(self) -> Calibration:
        """Calibration of the frames this camera delivers."""
        ...

    def read(self) -> NDArray[np.uint8]:
        """The next frame, BGR uint8 ``(H, W, 3)``; raise CameraError subclasses."""
        ...

    def close(self) -> None:
        """Release the device (idempotent)."""
        ...


def source_kind(source: str) -> SourceKind:
    """Classify a camera source string (see module docstring)."""
    if source.isdigit():
        return "device"
    if "://" in source:
        return "url"
    if "%" in source:
        return "sequence"
    return "file"


_OPEN_HINTS: dict[SourceKind, str] = {
    "device": "check that it is plugged in and not used by another program (ls /dev/video*)",
    "url": "check the URL and that the stream is reachable",
    "sequence": "check the pattern (e.g. frames_%04d.png) and that its first image exists",
    "file": "check the path and that OpenCV can decode the video",
}


def quiet_opencv() -> None:
    """Silence OpenCV's own log lines (``[ WARN:0] ... can't open camera by index``) on stderr.

    A camera that fails is reported once, as our one-line error. A user who set
    ``OPENCV_LOG_LEVEL`` keeps that level.
    """
    if "OPENCV_LOG_LEVEL" in os.environ:
        return
    if hasattr(cv2.utils, "logging"):  # OpenCV 5
        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    else:  # OpenCV 4: cv2.setLogLevel, 0 = silent
        opencv4: Any = cv2
        opencv4.setLogLevel(0)


class OpenCVCamera:
    """A camera read through ``cv2.VideoCapture``.

    Parameters
    ----------
    source : str
        Device index, URL, image-sequence pattern or video file (see module docstring).
    calibration : Calibration
        Calibration of the frames; their size must match it.
    capture_factory : callable, optional
        Builds the capture from ``int`` or ``str``; default ``cv2.VideoCapture`` (tests inject a
        stand-in for a physical device).

    Raises
    ------
    CameraError
        The source cannot be opened (one line: which source, what to check).
    """

    def __init__(
        self,
        source: str,
        calibration: Calibration,
        *,
        capture_factory: Callable[[Any], Any] = cv2.VideoCapture,
    ) -> None:
        self.source = source
        self.kind = source_kind(source)
        self._calibration = calibration
        if self.kind == "file" and not os.path.exists(source):
            raise CameraError(f"cannot open camera {source}: no such file; {_OPEN_HINTS['file']}")
        quiet_opencv()
        self._capture = capture_factory(int(source) if self.kind == "device" else source)
        if not self._capture.isOpened():
            self._capture.release()
            raise CameraError(f"cannot open camera {source}: {_OPEN_HINTS[self.kind]}")
        self.frames_read = 0

    @property
    def calibration(self) -> Calibration:
        """Calibration of the frames."""
        return self._calibration

    def read(self) -> NDArray[np.uint8]:
        """The next frame, BGR uint8 ``(H, W, 3)``.

        Raises
        ------
        CameraEndOfStream
            A file or image sequence has ended.
        CameraDisconnected
            A live source failed ``LIVE_READ_ATTEMPTS`` times in a row.
        ImageError
            The frame size differs from the calibration.
        """
        attempts = LIVE_READ_ATTEMPTS if self.kind in ("device", "url") else 1
        frame = None
        for _ in range(attempts):
            ok, frame = self._capture.read()
            if ok and frame is not None:
                break
        else:
            if self.kind in ("device", "url"):
                raise CameraDisconnected(
                    f"camera {self.source} stopped delivering frames after {self.frames_read} "
                    "(unplugged or stream lost); check the cable or connection"
                )
            raise CameraEndOfStream(
                f"camera source {self.source} ended after {self.frames_read} frames"
            )
        image = _to_bgr(np.asarray(frame))
        _check_size(image, self.source, self._calibration)
        self.frames_read += 1
        return image

    def video_time_ms(self) -> float:
        """The time of the frame just read, ms from the video's start (a video file's own frame
        times, ``CAP_PROP_POS_MSEC``; other sources give 0 or a meaningless value)."""
        return float(self._capture.get(cv2.CAP_PROP_POS_MSEC))

    def close(self) -> None:
        """Release the capture (idempotent)."""
        self._capture.release()


#: File names a :class:`FolderCamera` reads (lower case), the image formats OpenCV reads.
IMAGE_SUFFIXES = frozenset(
    {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".pnm", ".webp"}
)


class FolderCamera:
    """The images of a folder in name order (other files ignored): a finite source.

    Parameters
    ----------
    folder : str
        The folder.
    calibration : Calibration
        Calibration of the images; their size must match it.

    Raises
    ------
    CameraError
        The folder holds no image.
    """

    kind = "folder"

    def __init__(self, folder: str, calibration: Calibration) -> None:
        self.source = folder
        self._calibration = calibration
        self._paths = sorted(
            os.path.join(folder, name)
            for name in os.listdir(folder)
            if os.path.splitext(name)[1].lower() in IMAGE_SUFFIXES
        )
        if not self._paths:
            raise CameraError(
                f"camera folder {folder} holds no image ({', '.join(sorted(IMAGE_SUFFIXES))})"
            )
        self.frames_read = 0

    @property
    def calibration(self) -> Calibration:
        """Calibration of the images."""
        return self._calibration

    def read(self) -> NDArray[np.uint8]:
        """The next image, BGR uint8 ``(H, W, 3)`` (greyscale as three equal channels).

        Raises
        ------
        CameraEndOfStream
            Every image has been read.
        ImageError
            An image OpenCV cannot read, or of a size other than the calibration's.
        """
        if self.frames_read == len(self._paths):
            raise CameraEndOfStream(f"camera folder {self.source} ended after {self.frames_read}")
        path = self._paths[self.frames_read]
        image = cv2.imread(path, cv2.IMREAD_COLOR)
        if image is None:
            raise ImageError(f"image {path} cannot be read (not an image OpenCV reads)")
        bgr = _to_bgr(np.asarray(image))
        _check_size(bgr, path, self._calibration)
        self.frames_read += 1
        return bgr

    def close(self) -> None:
        """Nothing to release."""


def _check_size(image: NDArray[np.uint8], source: str, cal: Calibration) -> None:
    """Raise :class:`ImageError` unless ``image`` has the calibration's size."""
    height, width = image.shape[:2]
    if (width, height) != (cal.width, cal.height):
        raise ImageError(
            f"camera {source} delivers {width}x{height} frames but the calibration is "
            f"for {cal.width}x{cal.height}; use the calibration made for this camera"
        )


def _to_bgr(frame: NDArray[Any]) -> NDArray[np.uint8]:
    """BGR uint8 (H, W, 3) from what VideoCapture returns (grey or BGRA frames happen)."""
    if frame.dtype != np.uint8:
        raise ImageError(f"camera frames must be 8-bit, got {frame.dtype}")
    if frame.ndim == 2:
        frame = cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
    elif frame.shape[2] == 4:
        frame = cv2.cvtColor(frame, cv2.COLOR_BGRA2BGR)
    out: NDArray[np.uint8] = np.ascontiguousarray(frame)
    return out
