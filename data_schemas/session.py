"""The session document: facts that hold for a whole log, stored as MCAP metadata.

Written first by the recorder as metadata record ``bslam.session`` with a single key ``json``
(so it survives a crash), validated against ``bslam.Session``. :class:`Session` is its typed view.
"""

from __future__ import annotations

import json
import math
import uuid
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from data_schemas.calibration import Calibration, calibration_from_dict
from data_schemas.catalog import catalog_problem
from data_schemas.codec import loads, validate
from data_schemas.colors import appearance_problem, class_label
from data_schemas.errors import MissingMetadataError, SchemaError

SCHEMA_VERSION = 1


@dataclass(frozen=True)
class LandmarkSpec:
    """One entry of the landmark catalog: a name and what it looks like.

    Either ``color`` (a single-colour landmark, optional HSV override ``hsv_lo``/``hsv_hi``) or
    ``bands`` (a coded landmark: two or more colour names, top to bottom, equal heights; then
    ``color`` is None; optional HSV override per band, ``band_hsv``: ``(lo, hi)`` per band), or
    ``tag`` (a fiducial marker's id in the session's ``tag_dictionary``), or neither in a
    session without a camera (known by its name only: a beacon id, an imported dataset's
    landmark number). ``width_m`` and ``height_m``: its physical size (m), if known.
    """

    name: str
    color: str | None
    hsv_lo: tuple[int, int, int] | None = None
    hsv_hi: tuple[int, int, int] | None = None
    bands: tuple[str, ...] = ()
    band_hsv: tuple[tuple[tuple[int, ...], tuple[int, ...]], ...] = ()
    width_m: float | None = None
    height_m: float | None = None
    tag: int | None = None

    @property
    def label(self) -> str:
        """The landmark's class: ``"red"`` or ``"magenta-yellow"`` (see ``class_label``), or
        ``"tag-17"`` for a fiducial marker; a landmark known by its name only (no colour, no
        bands, no tag) is a class of its own, its name."""
        if self.tag is not None:
            return f"tag-{self.tag}"
        if self.color is None and not self.bands:
            return self.name
        return class_label(self.color, self.bands)


def shared_classes(landmarks: Sequence[LandmarkSpec]) -> dict[str, list[str]]:
    """Class label -> catalog names, for the classes several landmarks share (in catalog order)."""
    by_label: dict[str, list[str]] = {}
    for lm in landmarks:
        by_label.setdefault(lm.label, []).append(lm.name)
    return {label: names for label, names in by_label.items() if len(names) > 1}


def shared_reference_problem(
    landmarks: Sequence[LandmarkSpec], reference: Sequence[str]
) -> str | None:
    """Why the reference pair is not distinct by its looks, or None.

    Each reference landmark must be the only one of its class (colour or band code): the map's
    frame is fixed by them, so they must never be confused with another landmark.
    """
    for ref in reference:
        label = next((lm.label for lm in landmarks if lm.name == ref), None)
        twins = [lm.name for lm in landmarks if lm.label == label and lm.name != ref]
        if label is not None and twins:
            return (
                f"reference landmark {ref!r} shares its class {label!r} with {', '.join(twins)}; "
                "give each reference landmark a colour or band code of its own"
            )
    return None


@dataclass(frozen=True)
class Session:
    """Typed view of the session document (see ``data_schemas/schemas/bslam.Session.json``).

    Attributes
    ----------
    landmarks : tuple of LandmarkSpec
        The catalog, in log order.
    reference : (str, str)
        Names of the reference pair (L1 -> (0, 0), L2 -> (1, 0) in FL).
    vision_error_rad : float
        Bound eps on the bearing error.
    calibration : Calibration or None
        How image positions map to bearings; None in a session without a camera (its bearings
        come from ``/sensor/bearings``).
    simulated : bool
    range_m : (float, float) or None
        Nearest and farthest distance (m) a landmark can be seen from, if given.
    tag_dictionary : str
        The fiducial markers' dictionary (``4x4_50`` unless the document says).
    doc : dict
        The whole JSON document (robot settings, camera source, scenario, provenance, versions).
    """

    landmarks: tuple[LandmarkSpec, ...]
    reference: tuple[str, str]
    vision_error_rad: float
    calibration: Calibration | None
    simulated: bool
    doc: dict[str, Any] = field(repr=False, compare=False)
    range_m: tuple[float, float] | None = None
    tag_dictionary: str = "4x4_50"

    @property
    def scenario(self) -> dict[str, Any] | None:
        """The simulation scenario, for simulated sessions."""
        scenario: dict[str, Any] | None = self.doc.get("scenario")
        return scenario

    @property
    def session_id(self) -> str:
        """The session's unique id (logs older than the field: a hash of the document)."""
        given = self.doc.get("session_id")
        if isinstance(given, str) and given:
            return given
        return uuid.uuid5(uuid.NAMESPACE_OID, json.dumps(self.doc, separators=(",", ":"))).hex

    def landmark_names(self) -> list[str]:
        """Catalog names in order."""
        return [lm.name for lm in self.landmarks]

    @property
    def provenance(self) -> dict[str, Any] | None:
        """Where an imported session came from (importer, source files' SHA-256), else None."""
        given: dict[str, Any] | None = self.doc.get("provenance")
        return given

    def truth_landmarks_m(self) -> dict[str, tuple[float, float]] | None:
        """Landmark positions an outside reference measured (metres, its world frame), or None.

        For evaluation only: estimation never reads them.
        """
        truth = self.doc.get("truth")
        if truth is None:
            return None
        return {lm["name"]: (float(lm["x_m"]), float(lm["y_m"])) for lm in truth["landmarks"]}


def session_from_doc(doc: dict[str, Any], *, what: str = "session metadata") -> Session:
    """Validate a session document and build its typed view (raise SchemaError)."""
    no_camera = "camera" not in doc
    for i, entry in enumerate(doc.get("landmarks") or []):
        problem = (
            appearance_problem(entry, name_only=no_camera) if isinstance(entry, dict) else None
        )
        if problem:
            raise SchemaError(f"{what}: field 'landmarks.{i}': {problem}")
    validate("bslam.Session", doc, what=what)
    ref = doc["reference"]
    names = [lm["name"] for lm in doc["landmarks"]]
    wrong = catalog_problem(names, ref)
    if wrong is not None:
        raise SchemaError(f"{what}: field {wrong[0]!r}: {wrong[1]}")
    unknown = [
        lm["name"] for lm in doc.get("truth", {}).get("landmarks", []) if lm["name"] not in names
    ]
    if unknown:
        raise SchemaError(f"{what}: field 'truth.landmarks': {unknown[0]!r} is not in the catalog")
    specs = []
    for lm in doc["landmarks"]:
        hsv = lm.get("hsv")
        one = hsv if isinstance(hsv, dict) else None
        per_band = hsv if isinstance(hsv, list) else []
        specs.append(
            LandmarkSpec(
                lm["name"],
                lm.get("color"),
                tuple(one["lo"]) if one else None,
                tuple(one["hi"]) if one else None,
                tuple(lm.get("bands", ())),
                tuple((tuple(b["lo"]), tuple(b["hi"])) for b in per_band),
                float(lm["width"]) if "width" in lm else None,
                float(lm["height"]) if "height" in lm else None,
                int(lm["tag"]) if "tag" in lm else None,
            )
        )
    range_m = doc.get("range_m")
    if range_m is not None and not range_m[0] < range_m[1]:
        raise SchemaError(
            f"{what}: field 'range_m': nearest {range_m[0]:g} m must be below farthest "
            f"{range_m[1]:g} m"
        )
    return Session(
        landmarks=tuple(specs),
        reference=(ref[0], ref[1]),
        vision_error_rad=math.radians(float(doc["vision_error_deg"])),
        calibration=None if no_camera else calibration_from_dict(doc["camera"]["calibration"]),
        simulated=bool(doc["simulated"]),
        doc=doc,
        range_m=None if range_m is None else (float(range_m[0]), float(range_m[1])),
        tag_dictionary=str(doc.get("tag_dictionary", "4x4_50")),
    )


def session_from_metadata(metadata: dict[str, str]) -> Session:
    """Build the session from the ``bslam.session`` metadata record's key/value map."""
    text = metadata.get("json")
    if text is None:
        raise MissingMetadataError("session metadata record has no 'json' key")
    doc = loads(text, what="session metadata", error=MissingMetadataError)
    if not isinstance(doc, dict):
        raise MissingMetadataError("session metadata is not a JSON object")
    return session_from_doc(doc)
