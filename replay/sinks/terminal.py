"""A compact terminal view of a followed log: the latest keyframe and the map, updated in place.

For a robot without a display (``bslam record --live``, ``bslam process --follow``): one line
says which movement and keyframe were processed last and which landmarks that keyframe detected;
one line per landmark gives its estimate and its 80% credible ellipse (FL, unit |L1 L2|). On a
terminal the lines are rewritten in place (tqdm status lines, no scrolling); when the stream is
not a terminal (a file, a pipe) each movement prints one line instead.
"""

from __future__ import annotations

import math
import sys
from typing import IO, Any

import numpy as np
from tqdm import tqdm

from pipeline.estimate import chi2_2dof_quantile
from replay.records import (
    AssociationRecord,
    EstimateRecord,
    FrameRecord,
    MovementRecord,
    RunInfo,
)
from replay.stages import CREDIBLE_P


def ellipse_text(e: EstimateRecord, p: float = CREDIBLE_P) -> str:
    """``(x, y) ±a x b @ deg``: mean, semi-axes of the ``p`` credible ellipse, major axis angle."""
    vals, vecs = np.linalg.eigh(e.cov_fl)
    radii = np.sqrt(np.maximum(vals, 0.0) * chi2_2dof_quantile(p))
    angle = math.degrees(math.atan2(vecs[1, 1], vecs[0, 1])) % 180.0
    x, y = (float(v) for v in e.mean_fl)
    return f"({x:+.3f}, {y:+.3f}) ±{radii[1]:.3f} x {radii[0]:.3f} @ {angle:3.0f}°"


def detected_text(frame: FrameRecord) -> str:
    """Landmarks of a frame: name and bearing (deg) when detected, ``name -`` when not."""
    parts = []
    for name, d in frame.detections.items():
        b = d.bearing_rad if d.visible else None
        parts.append(f"{name} -" if b is None else f"{name} {math.degrees(b):+.0f}°")
    return "  ".join(parts)


class TerminalView:
    """A sink that shows the latest keyframe and the map (see the module docstring).

    Parameters
    ----------
    stream : text stream, optional
        Where to write (default stderr).
    """

    wants_all_frames = False
    wants_images = False

    def __init__(self, stream: IO[str] | None = None) -> None:
        self._stream = stream or sys.stderr
        self._in_place = self._stream.isatty()
        self._lines: list[tqdm[Any]] = []
        self._names: list[str] = []
        self._keyframe = ""
        self._movements = 0
        self._used = 0

    def start(self, run: RunInfo) -> None:
        self._names = [n for n in run.session.landmark_names() if n not in run.session.reference]
        self._header = f"{run.log_name}: "
        if self._in_place:
            self._lines = [
                tqdm(bar_format="{desc}", position=i, file=self._stream, leave=True)
                for i in range(2 + len(self._names))
            ]
            self._set(0, f"{self._header}waiting for the first movement")
            for i, name in enumerate(self._names):
                self._set(2 + i, f"  {name}: not mapped yet")

    def frame(self, frame: FrameRecord) -> None:
        if frame.keyframe is None:
            return
        index, phase = frame.keyframe
        self._keyframe = f"keyframe {index} {phase}: {detected_text(frame)}"
        if self._in_place:
            self._set(1, self._keyframe)

    def movement(self, record: MovementRecord) -> None:
        self._movements += 1
        self._used += record.ok
        status = f"movement {record.index} {record.status}"
        head = f"{self._header}{status} ({self._used}/{self._movements} used)"
        if not self._in_place:
            maps = "; ".join(
                f"{n} {ellipse_text(e)}" for n, e in record.estimates.items() if n in self._names
            )
            print(f"{head} | {self._keyframe} | {maps}", file=self._stream, flush=True)
            return
        self._set(0, head)
        for i, name in enumerate(self._names):
            e = record.estimates.get(name)
            if e is not None:
                self._set(2 + i, f"  {name}: {ellipse_text(e)}")

    def association(self, record: AssociationRecord) -> None:
        text = f"{self._header}{record.text()}"
        for name, why in {**record.retracted, **record.named_at_end}.items():
            text += f"; {name} {why}"
        for label, why in record.reports.items():
            text += f"; {label}: {why}"
        if self._in_place:
            self._set(1, text)
        else:
            print(text, file=self._stream, flush=True)

    def finish(self) -> None:
        for line in self._lines:
            line.close()
        self._lines = []

    def _set(self, i: int, text: str) -> None:
        self._lines[i].set_description_str(text, refresh=True)
