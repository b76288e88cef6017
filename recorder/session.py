"""Build the session document the recorder writes first into every log (``bslam.session``)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Literal

from data_schemas.calibration import Calibration
from data_schemas.session import SCHEMA_VERSION, LandmarkSpec, session_from_doc
from recorder.writer import software_version


def landmark_entry(spec: LandmarkSpec) -> dict[str, Any]:
    """JSON form of one catalog entry (``hsv`` only when the colour class is overridden)."""
    entry: dict[str, Any] = {"name": spec.name, "color": spec.color}
    if spec.hsv_lo is not None and spec.hsv_hi is not None:
        entry["hsv"] = {"lo": list(spec.hsv_lo), "hi": list(spec.hsv_hi)}
    return entry


def build_session_doc(
    *,
    created_unix_ns: int,
    robot: dict[str, Any],
    camera_source: str,
    calibration: Calibration,
    frame_rate_hz: float,
    encoding: Literal["png", "bgr8"],
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
        The document does not validate (names the field).
    """
    doc: dict[str, Any] = {
        "schema_version": SCHEMA_VERSION,
        "software_version": software_version(),
        "created_unix_ns": int(created_unix_ns),
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
    session_from_doc(doc)
    return doc
