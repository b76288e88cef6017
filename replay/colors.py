"""``bslam calibrate colors``: learn a catalog's HSV boxes from marked frames, write the catalog.

Files in, files out around :func:`pipeline.bearings.learn_colors.learn_catalog_boxes`:

* frames: image files OpenCV reads (PNG, JPEG, ...), colour;
* marks (JSON): ``{"marks": [{"frame": "f1.png", "landmark": "L1", "points": [[x, y], ...]},
  {"frame": "f1.png", "landmark": "L3", "columns": [x0, x1]}, ...]}``: pixel coordinates
  (x right, y down); ``frame`` is a path as given on the command line or its file name. Mark
  every catalog landmark that shows in a marked frame (an unmarked one counts as background);
  choose frames where each landmark is whole in view or absent;
* catalog: the landmark file of ``bslam record`` (:func:`recorder.session.load_landmark_file`);
  the catalog written is the same file with each learned colour's box (``hsv``: one box for a
  single-colour landmark, one per band for a coded one).
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from data_schemas.errors import BslamError, ImageError
from data_schemas.outputs import OutputGuard
from pipeline.bearings.learn_colors import ColorMark, LearnedBox, learn_catalog_boxes
from recorder.session import landmark_entry, load_landmark_file


class MarksFileError(BslamError):
    """The marks file is unreadable or malformed."""


@dataclass(frozen=True)
class ColorCalibration:
    """What ``calibrate colors`` learned: one box per colour marked, and the colours of the
    catalog no mark showed (they keep their boxes)."""

    learned: list[LearnedBox]
    unmarked: list[str]


def calibrate_colors(
    frame_paths: Sequence[str | os.PathLike[str]],
    marks_path: str | os.PathLike[str],
    catalog_path: str | os.PathLike[str],
    out_path: str | os.PathLike[str],
    *,
    force: bool = False,
) -> ColorCalibration:
    """Learn the boxes from the marked frames and write the catalog to ``out_path``.

    Raises
    ------
    BslamError
        An unreadable or malformed file, a greyscale frame, a mark that cannot be used, an
        output that may not be written (one line each).
    """
    guard = OutputGuard([*frame_paths, marks_path, catalog_path], force=force)
    guard.claim(out_path, what="catalog")
    catalog = load_landmark_file(catalog_path)
    with open(catalog_path, encoding="utf-8") as f:
        doc: dict[str, Any] = json.load(f)
    frames = [_read_frame(p) for p in frame_paths]
    marks = _read_marks(marks_path, [os.fspath(p) for p in frame_paths])
    specs, learned = learn_catalog_boxes(frames, marks, catalog.landmarks)
    doc["landmarks"] = [landmark_entry(s) for s in specs]
    guard.write_text(out_path, json.dumps(doc, indent=2) + "\n")
    colors = {c for s in catalog.landmarks for c in (s.bands or (s.color,)) if c}
    return ColorCalibration(learned, sorted(colors - {b.color for b in learned}))


def _read_frame(path: str | os.PathLike[str]) -> NDArray[np.uint8]:
    """A colour frame (H, W, 3) uint8 BGR; raise ImageError."""
    image = cv2.imread(os.fspath(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise ImageError(f"cannot read frame {os.fspath(path)}: not an image OpenCV can read")
    if image.dtype != np.uint8:
        raise ImageError(f"frame {os.fspath(path)} has {image.dtype} pixels; give 8-bit frames")
    if image.ndim == 3 and image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    if image.ndim != 3 or image.shape[2] != 3:
        raise ImageError(
            f"frame {os.fspath(path)} is greyscale: colours can only be learned from colour frames"
        )
    return np.asarray(image, np.uint8)


def _read_marks(path: str | os.PathLike[str], frames: list[str]) -> list[ColorMark]:
    """The marks of ``path``, frames resolved to indices into ``frames``."""
    name = os.fspath(path)
    try:
        with open(path, encoding="utf-8") as f:
            doc = json.load(f)
    except OSError as exc:
        raise MarksFileError(f"cannot read marks file {name}: {exc.strerror}") from None
    except json.JSONDecodeError as exc:
        raise MarksFileError(f"marks file {name} is not valid JSON ({exc})") from None
    entries = doc.get("marks") if isinstance(doc, dict) else None
    if not isinstance(entries, list):
        raise MarksFileError(f'marks file {name}: expected {{"marks": [...]}}')
    out = []
    for i, entry in enumerate(entries):
        where = f"marks file {name}: marks[{i}]"
        if not isinstance(entry, dict) or not isinstance(entry.get("landmark"), str):
            raise MarksFileError(f"{where}: needs 'frame', 'landmark' and 'points' or 'columns'")
        frame = _frame_index(str(entry.get("frame")), frames, where)
        points, columns = entry.get("points"), entry.get("columns")
        try:
            if points is not None and columns is None:
                pts = tuple((float(x), float(y)) for x, y in points)
                if not pts or not all(np.isfinite(pts).ravel()):
                    raise ValueError
                out.append(ColorMark(frame, entry["landmark"], points=pts))
            elif columns is not None and points is None:
                x0, x1 = (int(c) for c in columns)
                out.append(ColorMark(frame, entry["landmark"], columns=(x0, x1)))
            else:
                raise MarksFileError(f"{where}: give either 'points' or 'columns'")
        except (TypeError, ValueError):
            raise MarksFileError(
                f"{where}: 'points' must be [[x, y], ...] and 'columns' [first, last] (pixels)"
            ) from None
    return out


def _frame_index(frame: str, frames: list[str], where: str) -> int:
    """Index of ``frame`` (a path as given, or a file name) among ``frames``."""
    exact = [k for k, p in enumerate(frames) if p == frame]
    named = [k for k, p in enumerate(frames) if Path(p).name == frame]
    found = exact or named
    if len(found) != 1:
        given = ", ".join(Path(p).name for p in frames)
        what = "is not among" if not found else "names several of"
        raise MarksFileError(f"{where}: frame {frame!r} {what} the frames given ({given})")
    return found[0]
