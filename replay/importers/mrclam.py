"""UTIAS MRCLAM (Leung et al. 2011) text files of one robot into a bearing-slam log.

A dataset folder holds, for robots N = 1..5 (white-space separated, ``#`` comment lines):

* ``RobotN_Odometry.dat``: ``time_s v_mps omega_radps``, the robot's velocity commands;
  integrated into ``/robot/odometry_pose`` (:mod:`replay.importers.odometry`);
* ``RobotN_Measurement.dat``: ``time_s barcode range_m bearing_rad``, what its camera saw. The
  range is ignored (bearings only). A barcode is mapped to a subject by ``Barcodes.dat``
  (``subject barcode``); sightings of the other robots (subjects without landmark truth) and of
  barcodes missing from the table are dropped and counted;
* ``Landmark_Groundtruth.dat``: ``subject x_m y_m x_std_m y_std_m`` by motion capture: the
  catalog (landmark ``L<subject>``) and the session's truth, evaluation only;
* ``RobotN_Groundtruth.dat``: ``time_s x_m y_m heading_rad`` by motion capture:
  ``/truth/robot_pose``, evaluation only.

The barcode table is checked against the truth: a landmark whose sightings point, in median,
more than :data:`SUSPECT_BEARING_DEG` away from where the truth puts it is reported (a note),
since a wrong table silently gives a wrong map. ``overrides`` (``--barcode SUBJECT=BARCODE``)
correct the table without editing the dataset.
"""

from __future__ import annotations

import bisect
import itertools
import math
import statistics
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from data_schemas.angles import wrap_rad
from replay.defaults import IMPORT_VISION_ERROR_DEG
from replay.importers.odometry import integrate_velocities
from replay.importers.source import (
    ImportedLog,
    ImportSourceError,
    Message,
    SourceFile,
    bearing_set,
    imported_session,
    in_time_order,
    odometry_pose,
    require_files,
    truth_pose,
)
from replay.importers.text import Row, rows

#: Raised whenever the same files would import differently.
MRCLAM_IMPORTER_VERSION = 1
#: A landmark whose sightings are this far (median, degrees) from the truth's bearing is reported.
SUSPECT_BEARING_DEG = 10.0
#: How far a printed time may be from its row's place on a regular grid (half of 0.1 s, the
#: last digit of 5 significant digits below 10,000 s), :func:`strict_times`.
GRID_TOLERANCE_NS = 50_000_001
#: The front end named in each ``/sensor/bearings`` message.
SOURCE = "mrclam camera"


def landmark_name(subject: int) -> str:
    """Catalog name of MRCLAM landmark ``subject``."""
    return f"L{subject}"


@dataclass(frozen=True)
class MrclamImporter:
    """One robot of an MRCLAM dataset folder (module docstring)."""

    folder: Path
    robot: int
    reference: tuple[str, str] | None = None
    vision_error_deg: float = IMPORT_VISION_ERROR_DEG
    overrides: Mapping[int, int] = field(default_factory=dict)

    @property
    def inputs(self) -> Sequence[SourceFile]:
        """The five files one robot's import reads."""
        n = self.robot
        return (
            SourceFile("odometry", self.folder / f"Robot{n}_Odometry.dat"),
            SourceFile("bearings", self.folder / f"Robot{n}_Measurement.dat"),
            SourceFile("barcodes", self.folder / "Barcodes.dat"),
            SourceFile("landmark truth", self.folder / "Landmark_Groundtruth.dat"),
            SourceFile("robot truth", self.folder / f"Robot{n}_Groundtruth.dat"),
        )

    def read(self) -> ImportedLog:
        """Read the robot's files into a log (raise :class:`ImportSourceError` on a bad one)."""
        if not self.folder.is_dir():
            raise ImportSourceError(f"MRCLAM dataset folder {self.folder} does not exist")
        require_files(self.inputs)
        odo, meas, codes, lm_truth, robot_truth = (f.path for f in self.inputs)
        landmarks = read_landmarks(lm_truth)
        subject_of = read_barcodes(codes)
        for subject, barcode in self.overrides.items():
            subject_of = {b: s for b, s in subject_of.items() if s != subject}
            subject_of[barcode] = subject
        sightings, notes = read_sightings(meas, subject_of, landmarks)
        truth = read_poses(robot_truth, what="robot truth")
        notes += barcode_check(sightings, truth, landmarks, subject_of)
        counts = Counter(name for _, name, _ in sightings)
        reference = self.reference or _most_seen(counts)
        options: dict[str, Any] = {
            "robot": self.robot,
            "reference": list(reference),
            "vision_error_deg": self.vision_error_deg,
        }
        if self.overrides:
            options["barcodes"] = {str(s): b for s, b in sorted(self.overrides.items())}
        doc = imported_session(
            kind="mrclam",
            importer_version=MRCLAM_IMPORTER_VERSION,
            files=self.inputs,
            options=options,
            landmarks=list(landmarks),
            reference=reference,
            vision_error_deg=self.vision_error_deg,
            truth={
                "source": "motion capture (MRCLAM Landmark_Groundtruth.dat)",
                "landmarks": [{"name": n, "x_m": x, "y_m": y} for n, (x, y) in landmarks.items()],
            },
        )
        bearings: list[Message] = []
        for t_ns, name, bearing in sightings:
            entry = {"landmark": name, "bearing_rad": bearing}
            if bearings and bearings[-1].t_ns == t_ns:
                bearings[-1].doc["bearings"].append(entry)
            else:
                bearings.append(bearing_set(t_ns, SOURCE, [entry]))
        times, v, w = read_velocities(odo)
        odometry = [
            odometry_pose(t, *pose)
            for t, pose in zip(times, integrate_velocities(times, v, w), strict=True)
        ]
        truth_msgs = [truth_pose(t, *pose) for t, pose in truth]
        unseen = [n for n in landmarks if n not in counts]
        if unseen:
            notes.append(f"robot {self.robot} never sees {', '.join(unseen)}")
        messages = in_time_order(odometry, bearings, truth_msgs)
        return ImportedLog(doc, messages, len(messages), notes)


def _fields(row: Row, n: int) -> None:
    if len(row.fields) < n:
        raise row.fail(f"{len(row.fields)} fields, expected {n}")


def read_landmarks(path: Path) -> dict[str, tuple[float, float]]:
    """``Landmark_Groundtruth.dat``: catalog name -> true position (m), in file order."""
    out: dict[str, tuple[float, float]] = {}
    for row in rows(path, what="landmark truth"):
        _fields(row, 3)
        name = landmark_name(row.integer(0, "subject"))
        if name in out:
            raise row.fail(f"landmark subject {row.fields[0]} is listed twice")
        out[name] = (row.number(1, "x_m"), row.number(2, "y_m"))
    if len(out) < 2:
        raise ImportSourceError(f"landmark truth file {path}: fewer than two landmarks")
    return out


def read_barcodes(path: Path) -> dict[int, int]:
    """``Barcodes.dat``: barcode -> subject."""
    out: dict[int, int] = {}
    for row in rows(path, what="barcodes"):
        _fields(row, 2)
        subject, barcode = row.integer(0, "subject"), row.integer(1, "barcode")
        if barcode in out:
            raise row.fail(f"barcode {barcode} is given to subjects {out[barcode]} and {subject}")
        out[barcode] = subject
    return out


def read_sightings(
    path: Path, subject_of: Mapping[int, int], landmarks: Mapping[str, object]
) -> tuple[list[tuple[int, str, float]], list[str]]:
    """``RobotN_Measurement.dat``: (time ns, landmark, bearing rad) of each landmark sighting,
    and notes on what was dropped (other robots, unknown barcodes)."""
    out: list[tuple[int, str, float]] = []
    robots = unknown = 0
    last_ns = -1
    for row in rows(path, what="bearings"):
        _fields(row, 4)
        t_ns = row.time_ns(0, "time")
        if t_ns < last_ns:
            raise row.fail("times must not decrease")
        last_ns = t_ns
        barcode = row.integer(1, "barcode")
        bearing = wrap_rad(row.number(3, "bearing_rad"))
        subject = subject_of.get(barcode)
        if subject is None:
            unknown += 1
            continue
        name = landmark_name(subject)
        if name not in landmarks:
            robots += 1
            continue
        out.append((t_ns, name, bearing))
    notes = [f"dropped {robots} sightings of other robots (bearings to landmarks only)"]
    if unknown:
        notes.append(f"dropped {unknown} sightings of barcodes missing from the barcode table")
    return out, notes


def read_velocities(path: Path) -> tuple[list[int], list[float], list[float]]:
    """``RobotN_Odometry.dat``: times (ns, strictly increasing), speeds (m/s), turn rates."""
    table = list(rows(path, what="odometry"))
    if not table:
        raise ImportSourceError(f"odometry file {path} has no rows")
    for row in table:
        _fields(row, 3)
    times = strict_times(table)
    v = [row.number(1, "v_mps") for row in table]
    w = [row.number(2, "omega_radps") for row in table]
    return times, v, w


def read_poses(path: Path, *, what: str) -> list[tuple[int, tuple[float, float, float]]]:
    """``RobotN_Groundtruth.dat``: (time ns, (x m, y m, heading rad in [-pi, pi)))."""
    table = list(rows(path, what=what))
    for row in table:
        _fields(row, 4)
    times = strict_times(table)
    return [
        (t, (row.number(1, "x_m"), row.number(2, "y_m"), wrap_rad(row.number(3, "heading"))))
        for t, row in zip(times, table, strict=True)
    ]


def strict_times(table: Sequence[Row]) -> list[int]:
    """The rows' times (ns), strictly increasing, from the first field.

    A file sampled on a regular grid but printed with too few digits (the 50 Hz MRCLAM files
    printed with 5 significant digits: from 1000 s on, five rows share each 0.1 s) gets its grid
    back: ``t_0 + i dt``, ``dt`` the first rows' spacing, accepted only if every printed time
    is within :data:`GRID_TOLERANCE_NS` of it.

    Raises
    ------
    ImportSourceError
        A time decreases, or repeats in a file that is not such a grid (names the line).
    """
    times = [row.time_ns(0, "time") for row in table]
    repeat = None
    for i in range(1, len(times)):
        if times[i] < times[i - 1]:
            raise table[i].fail("times must not decrease")
        if repeat is None and times[i] == times[i - 1]:
            repeat = i
    if repeat is None:
        return times
    head = times[: min(repeat, 101)]
    if len(head) >= 3:
        dt = statistics.median(b - a for a, b in itertools.pairwise(head))
        grid = [times[0] + round(i * dt) for i in range(len(times))]
        if all(abs(t - g) <= GRID_TOLERANCE_NS for t, g in zip(times, grid, strict=True)):
            return grid
    raise table[repeat].fail("time repeats the previous row's (times must increase strictly)")


def barcode_check(
    sightings: Sequence[tuple[int, str, float]],
    truth: Sequence[tuple[int, tuple[float, float, float]]],
    landmarks: Mapping[str, tuple[float, float]],
    subject_of: Mapping[int, int],
) -> list[str]:
    """Notes on landmarks whose sightings disagree with the truth (a wrong barcode table).

    For each sighting the robot's true pose is interpolated between the truth rows around it
    (if they are at most 1 s apart). A landmark whose sightings are, in median, more than
    :data:`SUSPECT_BEARING_DEG` from the truth's bearing is reported, with the landmark its
    barcode fits best (the least median error) as the correction to try.
    """
    times = [t for t, _ in truth]
    # per table name: (true robot pose, measured bearing) of each sighting
    seen: dict[str, list[tuple[float, float, float, float]]] = {}
    for t_ns, name, bearing in sightings:
        i = bisect.bisect_right(times, t_ns)
        if i == 0 or i == len(times) or times[i] - times[i - 1] > 1_000_000_000:
            continue
        (x0, y0, h0), (x1, y1, h1) = truth[i - 1][1], truth[i][1]
        f = (t_ns - times[i - 1]) / (times[i] - times[i - 1])
        pose = (x0 + f * (x1 - x0), y0 + f * (y1 - y0), h0 + f * wrap_rad(h1 - h0), bearing)
        seen.setdefault(name, []).append(pose)

    def median_deg(
        views: list[tuple[float, float, float, float]], at: tuple[float, float]
    ) -> float:
        errs = [abs(wrap_rad(b - math.atan2(at[1] - y, at[0] - x) + h)) for x, y, h, b in views]
        return math.degrees(statistics.median(errs))

    barcode_of = {landmark_name(s): b for b, s in subject_of.items()}
    notes = []
    for name, views in seen.items():
        error_deg = median_deg(views, landmarks[name])
        if error_deg <= SUSPECT_BEARING_DEG:
            continue
        fits = {other: median_deg(views, xy) for other, xy in landmarks.items()}
        best = min(fits, key=fits.__getitem__)
        fix = (
            f"it fits {best} ({fits[best]:.1f} deg): try --barcode {best[1:]}={barcode_of[name]}"
            if fits[best] <= SUSPECT_BEARING_DEG
            else "it fits no landmark; correct it with --barcode SUBJECT=BARCODE"
        )
        notes.append(
            f"check the barcode table: {name} (barcode {barcode_of[name]}) is seen "
            f"{error_deg:.0f} deg (median of {len(views)}) from where the truth puts it; {fix}"
        )
    return notes


def _most_seen(counts: Counter[str]) -> tuple[str, str]:
    top = [name for name, _ in counts.most_common(2)]
    if len(top) < 2:
        raise ImportSourceError(
            "the robot sees fewer than two landmarks: no reference pair (check the barcode table)"
        )
    return top[0], top[1]
