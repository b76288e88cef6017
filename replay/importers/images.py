"""A folder of images with a timestamps file (and an odometry CSV) into a bearing-slam log.

Timestamps CSV: a header, then one row per frame::

    file,t_s

``file`` an image in the folder (any format OpenCV reads; greyscale as three equal channels),
``t_s`` its capture time in seconds (>= 0, strictly increasing). Frames are stored lossless
(PNG) on ``/camera/panorama``. The odometry CSV, if given, is the CSV importer's (poses or
velocities, :mod:`replay.importers.csv_files`); the calibration file and the landmark file are
those ``bslam record`` reads.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from data_schemas.calibration import Calibration
from data_schemas.registry import CAMERA_TOPIC
from recorder.frames import frame_message
from recorder.session import landmark_entry, load_calibration_file, load_landmark_file
from replay.importers.csv_files import read_odometry
from replay.importers.source import (
    ImportedLog,
    ImportSourceError,
    Message,
    SourceFile,
    imported_session,
    in_time_order,
    require_files,
)
from replay.importers.text import rows, with_columns

#: Raised whenever the same files would import differently.
IMAGES_IMPORTER_VERSION = 1
PNG_LEVEL = 1


@dataclass(frozen=True)
class ImageFolderImporter:
    """Images + timestamps CSV (+ odometry CSV) + calibration + landmark file (module
    docstring)."""

    folder: Path
    timestamps: Path
    calibration: Path
    landmarks: Path
    odometry: Path | None = None

    def frames(self) -> list[tuple[int, Path]]:
        """(time ns, image path) of each row of the timestamps file."""
        col, table = with_columns(rows(self.timestamps, what="timestamps"), ("file", "t_s"))
        out: list[tuple[int, Path]] = []
        for row in table:
            t_ns = row.time_ns(col["t_s"])
            if out and t_ns <= out[-1][0]:
                raise row.fail("times must increase strictly (sort the rows by t_s)")
            path = self.folder / row.fields[col["file"]]
            if not path.is_file():
                raise row.fail(f"image {path} does not exist")
            out.append((t_ns, path))
        if not out:
            raise ImportSourceError(f"timestamps file {self.timestamps} lists no image")
        return out

    @property
    def inputs(self) -> Sequence[SourceFile]:
        """The timestamps, calibration, landmark and odometry files (images: see read)."""
        files = [
            SourceFile("timestamps", self.timestamps),
            SourceFile("calibration", self.calibration),
            SourceFile("landmarks", self.landmarks),
        ]
        if self.odometry is not None:
            files.append(SourceFile("odometry", self.odometry))
        return files

    def read(self) -> ImportedLog:
        """Check the files and list the frames; frames are read and encoded as they are written."""
        if not self.folder.is_dir():
            raise ImportSourceError(f"image folder {self.folder} does not exist")
        require_files(self.inputs)
        frames = self.frames()
        calibration = load_calibration_file(self.calibration)
        catalog = load_landmark_file(self.landmarks)
        odometry = [] if self.odometry is None else read_odometry(self.odometry)
        span_s = max(frames[-1][0] - frames[0][0], 1) * 1e-9
        camera = {
            "source": f"image folder {self.folder.name}",
            "calibration": calibration.to_dict(),
            "encoding": "png",
            "frame_rate_hz": round(max(len(frames) - 1, 1) / span_s, 6),
        }
        doc = imported_session(
            kind="images",
            importer_version=IMAGES_IMPORTER_VERSION,
            files=[*self.inputs, *(SourceFile("frame", p) for _, p in frames)],
            options={"odometry": self.odometry is not None},
            landmarks=[landmark_entry(lm) for lm in catalog.landmarks],
            reference=catalog.reference,
            vision_error_deg=math.degrees(catalog.vision_error_rad),
            range_m=catalog.range_m,
            camera=camera,
        )
        placeholders = [Message(t, CAMERA_TOPIC, {"path": str(p)}) for t, p in frames]
        ordered = in_time_order(placeholders, odometry)
        notes = [] if self.odometry is not None else ["no odometry: frames only"]
        return ImportedLog(doc, _encoded(ordered, calibration), len(ordered), notes)


def _encoded(ordered: list[Message], calibration: Calibration) -> Iterator[Message]:
    """The messages with each frame's image read and encoded (one at a time)."""
    import cv2

    for msg in ordered:
        if msg.topic != CAMERA_TOPIC:
            yield msg
            continue
        path = msg.doc["path"]
        image = cv2.imread(path, cv2.IMREAD_COLOR)
        if image is None:
            raise ImportSourceError(f"image {path} cannot be read (not an image OpenCV reads)")
        if image.shape[1] != calibration.width or image.shape[0] != calibration.height:
            raise ImportSourceError(
                f"image {path} is {image.shape[1]} x {image.shape[0]}, but the calibration is "
                f"{calibration.width} x {calibration.height}"
            )
        bgr = np.ascontiguousarray(image, np.uint8)
        frame = frame_message(bgr, msg.t_ns, encoding="png", png_level=PNG_LEVEL)
        yield Message(msg.t_ns, msg.topic, frame)
