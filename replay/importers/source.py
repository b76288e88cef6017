"""What an importer gives: a session document and time-ordered messages, with provenance.

An importer (:class:`Importer`) names the files it reads (``inputs``, so that no output is
written onto them) and reads them into an :class:`ImportedLog`. The session records where the
log came from (``provenance``: the importer, its version, every file's SHA-256) and keeps any
truth the source has for evaluation only (``truth``; the robot's true poses go on
``/truth/robot_pose``, a channel estimation never reads).
"""

from __future__ import annotations

import hashlib
import time
import uuid
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from data_schemas.errors import BslamError
from data_schemas.mcap.writer import software_version
from data_schemas.registry import BEARINGS_TOPIC, ODOMETRY_POSE_TOPIC, TRUTH_POSE_TOPIC
from data_schemas.session import SCHEMA_VERSION, session_from_doc
from data_schemas.stamps import stamp_from_ns


class ImportSourceError(BslamError):
    """A file to import is missing or malformed (the message names the file and the line)."""


@dataclass(frozen=True)
class SourceFile:
    """One file an importer reads, and what it gives the log (``role``)."""

    role: str
    path: Path

    def provenance(self) -> dict[str, Any]:
        """The file's provenance entry: role, name, SHA-256 of its bytes, size."""
        digest = hashlib.sha256()
        size = 0
        try:
            with self.path.open("rb") as stream:
                while block := stream.read(1 << 20):
                    digest.update(block)
                    size += len(block)
        except OSError as exc:
            raise ImportSourceError(f"cannot read {self.path}: {exc.strerror or exc}") from None
        return {
            "role": self.role,
            "name": self.path.name,
            "sha256": digest.hexdigest(),
            "bytes": size,
        }


@dataclass(frozen=True)
class Message:
    """One message of the imported log: its log time (ns: when the source had it, the order of
    the log), topic, JSON document (whose ``timestamp`` is the sensor time)."""

    t_ns: int
    topic: str
    doc: dict[str, Any]


@dataclass
class ImportedLog:
    """A source read into a log's content.

    Attributes
    ----------
    session_doc : dict
        The session document (``bslam.Session``), validated.
    messages : iterable of Message
        In log-time order (a list, or a generator that reads the source as it goes).
    total : int
        How many messages ``messages`` gives (for progress).
    notes : list of str
        What the importer left out or doubts (one line each), for the user.
    """

    session_doc: dict[str, Any]
    messages: Iterable[Message]
    total: int
    notes: list[str] = field(default_factory=list)


class Importer(Protocol):
    """What :func:`replay.importers.write.import_log` needs of an importer."""

    @property
    def inputs(self) -> Sequence[SourceFile]:
        """Every file the importer reads."""
        ...

    def read(self) -> ImportedLog:
        """Read the inputs (raise :class:`ImportSourceError` on a missing or bad file)."""
        ...


def require_files(files: Sequence[SourceFile]) -> None:
    """Raise :class:`ImportSourceError` naming the first file that is missing."""
    for f in files:
        if not f.path.is_file():
            raise ImportSourceError(f"{f.role} file {f.path} does not exist")


def imported_session(
    *,
    kind: str,
    importer_version: int,
    files: Sequence[SourceFile],
    options: dict[str, Any],
    landmarks: Sequence[str | dict[str, Any]],
    reference: tuple[str, str],
    vision_error_deg: float,
    truth: dict[str, Any] | None = None,
    camera: dict[str, Any] | None = None,
    range_m: tuple[float, float] | None = None,
) -> dict[str, Any]:
    """The session document of an imported log (no robot), validated.

    Parameters
    ----------
    kind : str
        The importer (``csv``, ``mrclam``).
    importer_version : int
        Its version: raised whenever the same files would import differently.
    files : sequence of SourceFile
        The files read (hashed here).
    options : dict
        The importer's settings, stored as given.
    landmarks : sequence of str or dict
        Catalog entries: a name (a landmark known by name only, in a session without a camera:
        its bearings come from ``/sensor/bearings``) or a session catalog entry (colour or
        bands, for a camera's frames).
    reference : (str, str)
        The reference pair L1, L2.
    vision_error_deg : float
        Bound eps on the bearing error, degrees.
    truth : dict, optional
        ``{"source": ..., "landmarks": [{"name", "x_m", "y_m"}]}``: evaluation only.
    camera : dict, optional
        The session's ``camera`` (source, calibration, encoding, frame rate) if frames are
        imported.
    range_m : (float, float), optional
        The catalog's nearest and farthest distance landmarks are seen from (the size gate).
    """
    doc: dict[str, Any] = {
        "schema_version": SCHEMA_VERSION,
        "software_version": software_version(),
        "created_unix_ns": time.time_ns(),
        "session_id": uuid.uuid4().hex,
        "simulated": False,
        "landmarks": [{"name": lm} if isinstance(lm, str) else lm for lm in landmarks],
        "reference": list(reference),
        "vision_error_deg": vision_error_deg,
        "provenance": {
            "kind": kind,
            "importer_version": importer_version,
            "files": [f.provenance() for f in files],
            "options": options,
        },
    }
    if truth is not None:
        doc["truth"] = truth
    if camera is not None:
        doc["camera"] = camera
    if range_m is not None:
        doc["range_m"] = list(range_m)
    try:
        session_from_doc(doc, what=f"{kind} import")
    except BslamError as exc:
        raise ImportSourceError(str(exc)) from None
    return doc


def bearing_set(t_ns: int, source: str, bearings: list[dict[str, Any]]) -> Message:
    """A ``/sensor/bearings`` message (``bslam.BearingSet``)."""
    doc = {"timestamp": stamp_from_ns(t_ns), "source": source, "bearings": bearings}
    return Message(t_ns, BEARINGS_TOPIC, doc)


def odometry_pose(t_ns: int, x_m: float, y_m: float, theta_rad: float) -> Message:
    """A ``/robot/odometry_pose`` message (``bslam.OdometryPose``)."""
    doc = {"timestamp": stamp_from_ns(t_ns), "x_m": x_m, "y_m": y_m, "theta_rad": theta_rad}
    return Message(t_ns, ODOMETRY_POSE_TOPIC, doc)


def truth_pose(t_ns: int, x_m: float, y_m: float, heading_rad: float) -> Message:
    """A ``/truth/robot_pose`` message (``bslam.GroundTruth``): evaluation only."""
    doc = {"timestamp": stamp_from_ns(t_ns), "x": x_m, "y": y_m, "heading": heading_rad}
    return Message(t_ns, TRUTH_POSE_TOPIC, doc)


def in_time_order(*streams: Sequence[Message]) -> list[Message]:
    """All messages sorted by time; among equal times the streams' order is kept."""
    merged = [m for stream in streams for m in stream]
    merged.sort(key=lambda m: m.t_ns)
    return merged
