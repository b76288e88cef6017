"""The session document the recorder writes first into every log (``bslam.session``), and the
calibration and landmark files ``bslam record`` reads to build it."""

from __future__ import annotations

import math
import os
import uuid
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from data_schemas.calibration import Calibration, calibration_from_dict, pinhole_from_camera_info
from data_schemas.codec import loads, validate
from data_schemas.errors import BslamError, CalibrationError, SchemaError
from data_schemas.inputs import read_text
from data_schemas.mcap.writer import software_version
from data_schemas.registry import ImageEncoding
from data_schemas.session import (
    SCHEMA_VERSION,
    LandmarkSpec,
    session_from_doc,
    shared_reference_problem,
)


def landmark_entry(spec: LandmarkSpec) -> dict[str, Any]:
    """JSON form of one catalog entry (``hsv`` only when the colour class is overridden, one box
    or one per band; ``tag`` for a fiducial; ``width``/``height`` when known)."""
    entry: dict[str, Any] = {"name": spec.name}
    if spec.bands:
        entry["bands"] = list(spec.bands)
    elif spec.tag is not None:
        entry["tag"] = spec.tag
    else:
        entry["color"] = spec.color
    if spec.hsv_lo is not None and spec.hsv_hi is not None:
        entry["hsv"] = {"lo": list(spec.hsv_lo), "hi": list(spec.hsv_hi)}
    if spec.band_hsv:
        entry["hsv"] = [{"lo": list(lo), "hi": list(hi)} for lo, hi in spec.band_hsv]
    if spec.width_m is not None:
        entry["width"] = spec.width_m
    if spec.height_m is not None:
        entry["height"] = spec.height_m
    return entry


def build_session_doc(
    *,
    created_unix_ns: int,
    robot: dict[str, Any],
    camera_source: str,
    calibration: Calibration,
    frame_rate_hz: float,
    encoding: ImageEncoding,
    landmarks: Sequence[LandmarkSpec],
    reference: tuple[str, str],
    vision_error_rad: float,
    scenario: dict[str, Any] | None = None,
    extra: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The session document, validated against ``bslam.Session``.

    Parameters
    ----------
    created_unix_ns : int
        Wall time of the session start (ns since the epoch); also the first log time.
    robot : dict
        Robot model and serial settings (``model``, ``port``, ``baudrate``, ``bytesize``,
        ``parity``, ``stopbits``, ``mm_per_pulse``, ``wheel_base_m``).
    camera_source : str
        Device index, URL, file or image-sequence pattern, as given by the user.
    calibration : Calibration
        Panorama calibration of the camera.
    frame_rate_hz : float
        Capture rate between keyframes.
    encoding : {"png", "bgr8"}
        How frames are stored on ``/camera/panorama``.
    landmarks : sequence of LandmarkSpec
        The landmark catalog.
    reference : (str, str)
        Reference pair (names in the catalog).
    vision_error_rad : float
        Bound eps on the bearing error, radians (stored in degrees).
    scenario : dict, optional
        The simulation scenario; its presence marks the session as simulated.
    extra : dict, optional
        More top-level keys (e.g. recorder settings), stored as given.

    Raises
    ------
    SchemaError
        The document does not validate (names the field), or a reference landmark shares its
        class (colour or band code) with another landmark.
    """
    doc: dict[str, Any] = {
        "schema_version": SCHEMA_VERSION,
        "software_version": software_version(),
        "created_unix_ns": int(created_unix_ns),
        "session_id": uuid.uuid4().hex,
        "simulated": scenario is not None,
        "robot": dict(robot),
        "camera": {
            "source": camera_source,
            "frame_rate_hz": float(frame_rate_hz),
            "encoding": encoding,
            "calibration": calibration.to_dict(),
        },
        "landmarks": [landmark_entry(lm) for lm in landmarks],
        "reference": list(reference),
        "vision_error_deg": math.degrees(vision_error_rad),
    }
    if scenario is not None:
        doc["scenario"] = scenario
    if extra:
        doc.update(extra)
    session = session_from_doc(doc)
    shared = shared_reference_problem(session.landmarks, session.reference)
    if shared:
        raise SchemaError(f"session: field 'reference': {shared}")
    return doc


def _read_json(path: str | os.PathLike[str], what: str) -> Any:
    text = read_text(path, what=f"{what} file", error=BslamError)
    return loads(text, what=f"{what} file {os.fspath(path)}", error=BslamError)


def load_calibration_file(path: str | os.PathLike[str]) -> Calibration:
    """Read a camera calibration file; raise CalibrationError.

    A JSON file with a ``model`` key is a ``bslam.Calibration``. Any other JSON, YAML or XML
    file is a pinhole camera's calibration as ROS's ``camera_info`` / ``camera_calibration``
    or OpenCV's ``FileStorage`` write it (:func:`~data_schemas.calibration.
    pinhole_from_camera_info`; an optional ``offset_deg`` gives the camera's mounted yaw).
    """
    name = os.fspath(path)
    if name.lower().endswith((".yaml", ".yml", ".xml")):
        return pinhole_from_camera_info(_read_file_storage(name))
    doc = _read_json(path, "calibration")
    if isinstance(doc, dict) and "model" not in doc:
        return pinhole_from_camera_info(doc)
    try:
        validate("bslam.Calibration", doc, what=f"calibration file {name}")
    except SchemaError as exc:
        raise CalibrationError(str(exc)) from None
    return calibration_from_dict(doc)


def _read_file_storage(path: str) -> dict[str, Any]:
    """The top-level keys of a YAML/XML file read by OpenCV's ``FileStorage`` (matrices as
    nested lists); raise CalibrationError."""
    import cv2

    if not os.path.isfile(path):
        raise CalibrationError(f"cannot read calibration file {path}: no such file")
    storage = _open_file_storage(cv2, path)
    if storage is None or not storage.isOpened():
        raise CalibrationError(
            f"calibration file {path} is not YAML/XML that OpenCV's FileStorage can read"
        )
    try:
        names = storage.root().keys()
        return {key: _node_value(storage.getNode(key)) for key in names}
    finally:
        storage.release()


def _open_file_storage(cv2: Any, path: str) -> Any:
    """``cv2.FileStorage`` of ``path``, or None. OpenCV 4 reads YAML only after a ``%YAML``
    directive, which ROS's camera_info files lack: such a file is read again with one."""
    try:
        return cv2.FileStorage(path, cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError):  # OpenCV's parser raises either on malformed text
        pass
    if not path.endswith((".yaml", ".yml")):
        return None
    try:
        with open(path, encoding="utf-8") as f:
            text = f.read()
        if text.startswith("%YAML"):
            return None
        flags = cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY
        return cv2.FileStorage("%YAML:1.0\n---\n" + text, flags)
    except (OSError, UnicodeDecodeError, cv2.error, SystemError):
        return None


def _node_value(node: Any) -> Any:
    """A FileStorage node as plain Python: a matrix as nested lists, maps, sequences, scalars."""
    if node.isMap():
        names = node.keys()
        if "dt" in names and "data" in names:  # an !!opencv-matrix
            return node.mat().tolist()
        return {key: _node_value(node.getNode(key)) for key in names}
    if node.isSeq():
        return [_node_value(node.at(i)) for i in range(node.size())]
    if node.isString():
        return node.string()
    if node.isInt() or node.isReal():
        return node.real()
    return None


@dataclass(frozen=True)
class LandmarkCatalog:
    """The landmark file of ``bslam record``: catalog, reference pair, vision error bound and the
    distances landmarks can be seen from (``range_m``, optional)."""

    landmarks: tuple[LandmarkSpec, ...]
    reference: tuple[str, str]
    vision_error_rad: float
    range_m: tuple[float, float] | None = None
    tag_dictionary: str | None = None

    def session_keys(self) -> dict[str, Any]:
        """Top-level session keys besides landmarks, reference and the error bound."""
        out: dict[str, Any] = {} if self.range_m is None else {"range_m": list(self.range_m)}
        if self.tag_dictionary is not None:
            out["tag_dictionary"] = self.tag_dictionary
        return out


def load_landmark_file(path: str | os.PathLike[str]) -> LandmarkCatalog:
    """Read a landmark file: ``{"landmarks": [{"name", "color"[, "hsv"]} or {"name", "bands"[,
    "hsv": [one box per band]]}, each with optional "width", "height" (m)], "reference": [a, b],
    "vision_error_deg": eps[, "range_m": [nearest, farthest]]}`` (the same keys as the session
    document); raise SchemaError (also when a reference landmark shares its class with
    another)."""
    doc = _read_json(path, "landmark")
    what = f"landmark file {os.fspath(path)}"
    if not isinstance(doc, dict):
        raise SchemaError(f"{what}: expected a JSON object with 'landmarks' and 'reference'")
    keys = {"landmarks", "reference", "vision_error_deg", "range_m", "tag_dictionary"}
    unknown = sorted(set(doc) - keys)
    if unknown:
        raise SchemaError(f"{what}: unknown key {unknown[0]!r}")
    probe = {
        "schema_version": SCHEMA_VERSION,
        "software_version": "",
        "created_unix_ns": 0,
        "simulated": False,
        "robot": {"model": "-", "port": "-", "baudrate": 1, "mm_per_pulse": 1, "wheel_base_m": 1},
        "camera": {"source": "-", "calibration": {"model": "unwrapped", "width": 1, "height": 1}},
        "vision_error_deg": 3.0,
    } | doc
    session = session_from_doc(probe, what=what)
    shared = shared_reference_problem(session.landmarks, session.reference)
    if shared:
        raise SchemaError(f"{what}: field 'reference': {shared}")
    return LandmarkCatalog(
        session.landmarks,
        session.reference,
        session.vision_error_rad,
        session.range_m,
        doc.get("tag_dictionary"),
    )
