"""A bearings CSV, an odometry CSV and a landmark catalog (JSON) into a bearing-slam log.

Bearings CSV: a header, then one row per bearing::

    t_s,landmark,bearing_rad[,std_rad]

``t_s`` seconds (>= 0, non-decreasing; rows with the same time form one ``/sensor/bearings``
message), ``landmark`` a catalog name, ``bearing_rad`` counter-clockwise from the robot's
forward direction (wrapped to [-pi, pi)), ``std_rad`` optional (> 0; empty: the session's
vision error bound decides).

Odometry CSV: a header naming one of two forms, then one row per time (strictly increasing):

* poses ``t_s,x_m,y_m,theta_rad``: the robot's integrated odometry, any fixed frame;
* velocities ``t_s,v_mps,omega_radps``: forward speed and turn rate from that row's time to
  the next, integrated here (:mod:`replay.importers.odometry`).

Catalog JSON::

    {"landmarks": [{"name": "A"}, {"name": "B", "x_m": 1.0, "y_m": 2.0}, ...],
     "reference": ["A", "B"], "vision_error_deg": 2.0}

``reference`` (default: the first two landmarks) and ``vision_error_deg`` (default
:data:`replay.defaults.IMPORT_VISION_ERROR_DEG`) are optional; surveyed positions ``x_m``,
``y_m`` (given for every landmark or none) become the session's truth, for evaluation only.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
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
)
from replay.importers.text import Row, rows, with_columns

#: Raised whenever the same files would import differently.
CSV_IMPORTER_VERSION = 1
BEARING_COLUMNS = ("t_s", "landmark", "bearing_rad")
POSE_COLUMNS = ("t_s", "x_m", "y_m", "theta_rad")
VELOCITY_COLUMNS = ("t_s", "v_mps", "omega_radps")


@dataclass(frozen=True)
class Catalog:
    """The landmark catalog file's content."""

    names: list[str]
    reference: tuple[str, str]
    vision_error_deg: float
    truth_m: dict[str, tuple[float, float]] | None


@dataclass(frozen=True)
class CsvImporter:
    """Bearings CSV + odometry CSV + catalog JSON (module docstring)."""

    bearings: Path
    odometry: Path
    catalog: Path
    reference: tuple[str, str] | None = None
    vision_error_deg: float | None = None

    @property
    def inputs(self) -> Sequence[SourceFile]:
        """The three files, with their roles."""
        return (
            SourceFile("bearings", self.bearings),
            SourceFile("odometry", self.odometry),
            SourceFile("landmarks", self.catalog),
        )

    def read(self) -> ImportedLog:
        """Read the three files into a log (raise :class:`ImportSourceError` on a bad one)."""
        require_files(self.inputs)
        catalog = read_catalog(self.catalog)
        reference = self.reference or catalog.reference
        eps_deg = self.vision_error_deg or catalog.vision_error_deg
        truth = None
        if catalog.truth_m is not None:
            truth = {
                "source": f"landmark catalog {self.catalog.name}",
                "landmarks": [
                    {"name": n, "x_m": xy[0], "y_m": xy[1]} for n, xy in catalog.truth_m.items()
                ],
            }
        options: dict[str, Any] = {"reference": list(reference), "vision_error_deg": eps_deg}
        doc = imported_session(
            kind="csv",
            importer_version=CSV_IMPORTER_VERSION,
            files=self.inputs,
            options=options,
            landmarks=catalog.names,
            reference=reference,
            vision_error_deg=eps_deg,
            truth=truth,
        )
        bearings = read_bearings(self.bearings, set(catalog.names), source=self.bearings.name)
        odometry = read_odometry(self.odometry)
        messages = in_time_order(odometry, bearings)
        return ImportedLog(doc, messages, len(messages))


def read_catalog(path: Path) -> Catalog:
    """Read and check the catalog JSON (module docstring)."""
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ImportSourceError(f"landmarks file {path} does not exist") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ImportSourceError(f"landmarks file {path} is not readable JSON ({exc})") from None

    def bad(problem: str) -> ImportSourceError:
        return ImportSourceError(f"landmarks file {path}: {problem}")

    entries = doc.get("landmarks") if isinstance(doc, dict) else None
    if not isinstance(entries, list) or len(entries) < 2:
        raise bad('expected {"landmarks": [{"name": ...}, ...]} with at least two landmarks')
    names: list[str] = []
    truth: dict[str, tuple[float, float]] = {}
    for i, entry in enumerate(entries):
        name = entry.get("name") if isinstance(entry, dict) else None
        if not isinstance(name, str) or not name:
            raise bad(f"landmarks[{i}] needs a non-empty string 'name'")
        if name in names:
            raise bad(f"landmarks[{i}]: duplicate name {name!r}")
        extra = set(entry) - {"name", "x_m", "y_m"}
        if extra:
            raise bad(f"landmarks[{i}]: unknown key {sorted(extra)[0]!r} (name, x_m, y_m)")
        names.append(name)
        if "x_m" in entry or "y_m" in entry:
            xy = (entry.get("x_m"), entry.get("y_m"))
            if not all(_finite(v) for v in xy):
                raise bad(f"landmarks[{i}]: x_m and y_m must both be finite numbers")
            truth[name] = (float(xy[0]), float(xy[1]))
    if truth and len(truth) != len(names):
        raise bad("give x_m, y_m for every landmark or for none")
    reference = doc.get("reference", names[:2])
    if (
        not isinstance(reference, list)
        or len(reference) != 2
        or not all(r in names for r in reference)
        or reference[0] == reference[1]
    ):
        raise bad(f"reference must be two different landmark names, got {reference!r}")
    eps = doc.get("vision_error_deg", IMPORT_VISION_ERROR_DEG)
    if not _finite(eps) or not 0 < eps < 90:
        raise bad(f"vision_error_deg must be a number in (0, 90), got {eps!r}")
    unknown = set(doc) - {"landmarks", "reference", "vision_error_deg"}
    if unknown:
        raise bad(f"unknown key {sorted(unknown)[0]!r} (landmarks, reference, vision_error_deg)")
    return Catalog(names, (reference[0], reference[1]), float(eps), truth or None)


def _finite(value: Any) -> bool:
    return type(value) in (int, float) and math.isfinite(value)


def read_bearings(path: Path, catalog: set[str], *, source: str) -> list[Message]:
    """The bearings CSV as ``/sensor/bearings`` messages, one per distinct time."""
    col, table = with_columns(rows(path, what="bearings"), BEARING_COLUMNS, ("std_rad",))
    out: list[Message] = []
    last_ns = -1
    for row in table:
        t_ns = row.time_ns(col["t_s"])
        if t_ns < last_ns:
            raise row.fail("times must not decrease (sort the rows by t_s)")
        name = row.fields[col["landmark"]]
        if name not in catalog:
            raise row.fail(
                f"landmark {name!r} is not in the catalog ({', '.join(sorted(catalog))})"
            )
        bearing: dict[str, Any] = {
            "landmark": name,
            "bearing_rad": wrap_rad(row.number(col["bearing_rad"], "bearing_rad")),
        }
        if "std_rad" in col and row.fields[col["std_rad"]]:
            std = row.number(col["std_rad"], "std_rad")
            if not std > 0:
                raise row.fail(f"std_rad is {std}; it must be > 0 (or empty)")
            bearing["std_rad"] = std
        if t_ns == last_ns:
            out[-1].doc["bearings"].append(bearing)
        else:
            out.append(bearing_set(t_ns, source, [bearing]))
        last_ns = t_ns
    return out


def read_odometry(path: Path) -> list[Message]:
    """The odometry CSV (poses or velocities) as ``/robot/odometry_pose`` messages."""
    table = rows(path, what="odometry")
    header = next(table, None)
    if header is None:
        raise ImportSourceError(f"odometry file {path} is empty")
    velocities = "v_mps" in header.fields
    columns = VELOCITY_COLUMNS if velocities else POSE_COLUMNS
    col, data = with_columns(_prepend(header, table), columns)
    times: list[int] = []
    values: list[tuple[float, ...]] = []
    for row in data:
        t_ns = row.time_ns(col["t_s"])
        if times and t_ns <= times[-1]:
            raise row.fail("times must increase strictly (sort the rows by t_s, no repeats)")
        times.append(t_ns)
        values.append(tuple(row.number(col[c], c) for c in columns[1:]))
    if velocities:
        v = [r[0] for r in values]
        w = [r[1] for r in values]
        poses = integrate_velocities(times, v, w)
    else:
        poses = [(r[0], r[1], r[2]) for r in values]
    return [odometry_pose(t, *pose) for t, pose in zip(times, poses, strict=True)]


def _prepend(first: Row, rest: Iterator[Row]) -> Iterator[Row]:
    yield first
    yield from rest
