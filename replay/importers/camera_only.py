"""``bslam record --no-robot``: every frame of a camera source, and odometry from a CSV, into a log.

No robot is driven: the frames come from a video file, an image-sequence pattern or a live
source (device index, URL) through :class:`recorder.camera.OpenCVCamera`, or from a folder's
images in name order (:class:`recorder.camera.FolderCamera`), and the odometry (if
any) from the CSV importer's odometry file (:func:`replay.importers.csv_files.read_odometry`,
poses or velocities). A log with frames and ``/robot/odometry_pose`` and no ``/robot/movement``
is processed by the driving path (docs/design.md).

Frame times, seconds from the source's start (the odometry CSV's ``t_s`` are in the same time):

* a video file: its own frame times (``CAP_PROP_POS_MSEC``); they must increase;
* an image sequence or a folder: frame ``i`` at ``i / rate_hz`` (images carry no times);
* a live source: the capture clock, from the first frame.

The log is written as it grows, as ``bslam record`` writes it: a stop signal (Ctrl-C, SIGTERM)
or a camera fault finishes and indexes it with what was captured.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from data_schemas.errors import CameraError
from data_schemas.mcap.writer import LogWriter, SettableClock
from data_schemas.registry import CAMERA_TOPIC, ImageEncoding
from recorder.camera import CameraEndOfStream, FolderCamera, OpenCVCamera
from recorder.frames import frame_message
from recorder.record import Progress, RecordResult, check_stop, stop_on_signals
from recorder.session import landmark_entry, load_calibration_file, load_landmark_file
from replay.importers.csv_files import read_odometry
from replay.importers.source import Message, SourceFile, imported_session

#: Raised whenever the same inputs would record differently.
CAMERA_ONLY_VERSION = 1
#: Frames between two progress calls.
PROGRESS_EVERY = 10


@dataclass(frozen=True)
class CameraOnlySpec:
    """A recording with no robot, as ``bslam record --no-robot`` takes it.

    Attributes
    ----------
    camera_source : str
        Video file, image-sequence pattern (``frames_%04d.png``), folder of images, device
        index or URL.
    calibration_file, landmark_file : Path
        As for ``bslam record``.
    odometry_file : Path or None
        Odometry CSV (``t_s,x_m,y_m,theta_rad`` or ``t_s,v_mps,omega_radps``), or none.
    rate_hz : float
        Frame rate of an image sequence or folder (images carry no times), frames per second.
    encoding : {"png", "bgr8"}
        Frame storage.
    png_level : int
        PNG level 0..3.
    chunk_compression : str
        ``""`` or ``"zstd"``.
    """

    camera_source: str
    calibration_file: Path
    landmark_file: Path
    odometry_file: Path | None
    rate_hz: float
    encoding: ImageEncoding = "png"
    png_level: int = 1
    chunk_compression: str = ""


def record_camera_only(
    out: str | os.PathLike[str],
    spec: CameraOnlySpec,
    *,
    progress: Callable[[Progress], None] | None = None,
) -> RecordResult:
    """Record every frame of ``spec.camera_source`` (and its odometry) into the log ``out``.

    Returns
    -------
    RecordResult
        ``movements`` 0, ``frames`` the frames written.

    Raises
    ------
    CameraError, SchemaError, ImportSourceError, LogError
        One line each; before the log exists if an input is bad, else after it is finished.
    RecordingInterrupted
        A stop signal; the log is finished and indexed first.
    """
    files = [
        SourceFile("calibration", spec.calibration_file),
        SourceFile("landmarks", spec.landmark_file),
    ]
    odometry: list[Message] = []
    if spec.odometry_file is not None:
        files.append(SourceFile("odometry", spec.odometry_file))
        odometry = read_odometry(spec.odometry_file)
    calibration = load_calibration_file(spec.calibration_file)
    catalog = load_landmark_file(spec.landmark_file)
    camera: FolderCamera | OpenCVCamera
    if os.path.isdir(spec.camera_source):
        camera = FolderCamera(spec.camera_source, calibration)
    else:
        camera = OpenCVCamera(spec.camera_source, calibration)
    doc = imported_session(
        kind="camera",
        importer_version=CAMERA_ONLY_VERSION,
        files=files,
        options={"camera_source": spec.camera_source, "rate_hz": spec.rate_hz},
        landmarks=[landmark_entry(lm) for lm in catalog.landmarks],
        reference=catalog.reference,
        vision_error_deg=math.degrees(catalog.vision_error_rad),
        range_m=catalog.range_m,
        camera={
            "source": spec.camera_source,
            "calibration": calibration.to_dict(),
            "encoding": spec.encoding,
            "frame_rate_hz": spec.rate_hz,
        },
    )
    clock = SettableClock()
    frames = 0
    pending = iter(odometry)
    next_odometry = next(pending, None)
    try:
        with (
            stop_on_signals(),
            LogWriter(out, doc, clock=clock, compression=spec.chunk_compression) as log,
        ):
            start_s: float | None = None
            last_ns = -1
            while True:
                check_stop()
                try:
                    image = camera.read()
                except CameraEndOfStream:
                    break
                if isinstance(camera, OpenCVCamera) and camera.kind == "file":
                    t_ns = round(camera.video_time_ms() * 1e6)
                elif camera.kind in ("sequence", "folder"):
                    t_ns = round(frames / spec.rate_hz * 1e9)
                else:
                    now_s = time.monotonic()
                    start_s = now_s if start_s is None else start_s
                    t_ns = round((now_s - start_s) * 1e9)
                if t_ns <= last_ns:
                    raise CameraError(
                        f"frame {frames} of {spec.camera_source} has time {t_ns * 1e-9:.6f} s, "
                        f"not after the previous frame's {last_ns * 1e-9:.6f} s; re-encode the "
                        "video with increasing frame times"
                    )
                last_ns = t_ns
                while next_odometry is not None and next_odometry.t_ns <= t_ns:
                    clock.t_ns = next_odometry.t_ns
                    log.write(next_odometry.topic, next_odometry.doc)
                    next_odometry = next(pending, None)
                clock.t_ns = t_ns
                message = frame_message(
                    image, t_ns, encoding=spec.encoding, png_level=spec.png_level
                )
                log.write(CAMERA_TOPIC, message)
                frames += 1
                if progress is not None and frames % PROGRESS_EVERY == 0:
                    progress(Progress(0, frames))
            while next_odometry is not None:
                clock.t_ns = next_odometry.t_ns
                log.write(next_odometry.topic, next_odometry.doc)
                next_odometry = next(pending, None)
    finally:
        camera.close()
    if progress is not None:
        progress(Progress(0, frames))
    return RecordResult(0, frames)
