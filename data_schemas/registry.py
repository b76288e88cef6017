"""Topic registry and schema loading.

Every channel a bearing-slam log may carry is listed in :data:`TOPICS` with the name of its
schema. Schemas are JSON Schema files in ``data_schemas/schemas`` (project) and
``data_schemas/foxglove`` (vendored Foxglove well-known schemas). :func:`schema_json` returns a
schema with every local ``$ref`` inlined: that self-contained text is what an MCAP writer
registers, so that Foxglove and other readers can use it without our files.
"""

from __future__ import annotations

import copy
import json
from dataclasses import dataclass
from functools import cache
from importlib import resources
from typing import Any, Literal

from data_schemas.errors import ImageError, UnknownSchemaError

SCHEMA_ENCODING = "jsonschema"
MESSAGE_ENCODING = "json"

#: MCAP metadata record holding the session document (key ``"json"``), written first.
SESSION_METADATA_NAME = "bslam.session"


#: Channel names the code refers to (every channel, with its schema, is in :data:`TOPICS`).
CAMERA_TOPIC = "/camera/panorama"
COMMAND_TOPIC = "/robot/command"
ODOMETRY_TOPIC = "/robot/odometry"
ODOMETRY_POSE_TOPIC = "/robot/odometry_pose"
BEARINGS_TOPIC = "/sensor/bearings"
MOVEMENT_TOPIC = "/robot/movement"
SIM_TRUTH_TOPIC = "/sim/ground_truth"
TRUTH_POSE_TOPIC = "/truth/robot_pose"


@dataclass(frozen=True)
class Topic:
    """A channel of a bearing-slam log."""

    name: str
    schema: str
    description: str


_TOPIC_LIST = [
    Topic(
        CAMERA_TOPIC,
        "foxglove.CompressedImage",
        "every captured frame, PNG (lossless); foxglove.RawImage 'bgr8' is accepted too",
    ),
    Topic(
        COMMAND_TOPIC,
        "bslam.RobotCommand",
        "each serial exchange: request, reply, outcome, latency",
    ),
    Topic(ODOMETRY_TOPIC, "bslam.Odometry", "wheel encoder counters"),
    Topic(
        ODOMETRY_POSE_TOPIC,
        "bslam.OdometryPose",
        "pose integrated from wheel odometry (m, rad, odometry frame), a driving robot's motion",
    ),
    Topic(
        BEARINGS_TOPIC,
        "bslam.BearingSet",
        "landmark bearings from any front end (beacon sensor, fiducials, another pipeline)",
    ),
    Topic(
        MOVEMENT_TOPIC,
        "bslam.Movement",
        "movement index, phase (start/end), keyframe at rest, commanded turn and distance",
    ),
    Topic("/log", "foxglove.Log", "recorder events and faults"),
    Topic(
        SIM_TRUTH_TOPIC,
        "bslam.GroundTruth",
        "simulation only: true robot pose x, y, heading (m, rad, world frame)",
    ),
    Topic(
        TRUTH_POSE_TOPIC,
        "bslam.GroundTruth",
        "imported logs, evaluation only: the robot's pose by an outside reference (motion "
        "capture; m, rad, the truth's world frame)",
    ),
    # Derived logs (`bslam process --out`): the pipeline's stages as channels.
    Topic("/pipeline/bearings", "bslam.Bearings", "derived: landmark bearings of one frame"),
    Topic(
        "/pipeline/particles_fr",
        "bslam.ParticlesFR",
        "derived: one movement's cones and landmark particles in the robot frame FR",
    ),
    Topic(
        "/pipeline/particles_fl",
        "bslam.ParticlesFL",
        "derived: belief and observation points in the landmark frame FL after one movement",
    ),
    Topic(
        "/pipeline/estimate",
        "bslam.Estimate",
        "derived: map after one movement (means, covariances in FL) or why it was skipped",
    ),
    # Derived logs, the same results in Foxglove's well-known schemas (its 3D panel), frame FL.
    Topic("/pipeline/map", "foxglove.SceneUpdate", "derived: the map (landmarks, 80% ellipses)"),
    Topic(
        "/pipeline/keyframe_poses",
        "foxglove.PosesInFrame",
        "derived: one movement's keyframe poses (O1, O2, heading O1 -> O2) in FL",
    ),
    Topic(
        "/pipeline/trajectory",
        "foxglove.PosesInFrame",
        "derived: every keyframe pose so far in FL",
    ),
    Topic("/pipeline/tf", "foxglove.FrameTransform", "derived: fl -> robot at each end keyframe"),
    Topic(
        "/pipeline/particles",
        "foxglove.PointCloud",
        "derived: the belief's particles in FL (fields x, y, z, landmark)",
    ),
    Topic(
        "/pipeline/association",
        "bslam.Association",
        "derived, landmarks that look alike: every keyframe detection with the final map",
    ),
]

#: Topic name -> :class:`Topic`.
TOPICS: dict[str, Topic] = {t.name: t for t in _TOPIC_LIST}

#: How a frame's pixels are stored on ``/camera/panorama`` (both lossless).
ImageEncoding = Literal["png", "bgr8"]

#: Schema of ``/camera/panorama`` for each encoding: PNG in ``foxglove.CompressedImage``
#: (``format``), BGR pixels in ``foxglove.RawImage`` (``encoding``, ``width``, ``height``,
#: ``step``).
IMAGE_SCHEMA: dict[ImageEncoding, str] = {
    "png": "foxglove.CompressedImage",
    "bgr8": "foxglove.RawImage",
}

#: Image schemas accepted on ``/camera/panorama``.
IMAGE_SCHEMAS = tuple(IMAGE_SCHEMA.values())


def image_encoding(schema: str) -> ImageEncoding:
    """The encoding a frame of schema ``schema`` is stored in (:data:`IMAGE_SCHEMA` inverted).

    Raises
    ------
    ImageError
        ``schema`` is not one of :data:`IMAGE_SCHEMAS`.
    """
    for encoding, name in IMAGE_SCHEMA.items():
        if name == schema:
            return encoding
    raise ImageError(
        f"/camera/panorama: schema {schema!r} is not an image schema; expected one of "
        + ", ".join(IMAGE_SCHEMAS)
    )


def _schema_file(name: str) -> str:
    folder = "foxglove" if name.startswith("foxglove.") else "schemas"
    path = resources.files("data_schemas").joinpath(folder, f"{name}.json")
    if not path.is_file():
        raise UnknownSchemaError(f"unknown schema {name!r}")
    return path.read_text(encoding="utf-8")


def _inline_refs(node: Any) -> Any:
    if isinstance(node, dict):
        ref = node.get("$ref")
        if isinstance(ref, str) and ref.endswith(".json"):
            target = dict(schema_dict(ref[: -len(".json")]))
            extra = {k: v for k, v in node.items() if k != "$ref"}
            target.update(extra)
            return target
        return {k: _inline_refs(v) for k, v in node.items()}
    if isinstance(node, list):
        return [_inline_refs(v) for v in node]
    return node


@cache
def _schema_cached(name: str) -> dict[str, Any]:
    result: dict[str, Any] = _inline_refs(json.loads(_schema_file(name)))
    return result


def schema_dict(name: str) -> dict[str, Any]:
    """The self-contained schema ``name`` (e.g. ``"bslam.Movement"``) as a fresh dict."""
    return copy.deepcopy(_schema_cached(name))


@cache
def schema_json(name: str) -> bytes:
    """The self-contained schema ``name`` as UTF-8 JSON bytes (what MCAP registers)."""
    return json.dumps(_schema_cached(name), separators=(",", ":")).encode()


def topic(name: str) -> Topic:
    """Look up a registered topic; raise :class:`UnknownSchemaError` for an unknown one."""
    try:
        return TOPICS[name]
    except KeyError:
        raise UnknownSchemaError(
            f"unknown topic {name!r}; known topics: {', '.join(sorted(TOPICS))}"
        ) from None
