"""Simulation scenarios: load, validate and describe a scenario file.

A scenario (JSON, schema ``bslam.Scenario``; metres, world frame with origin at an arena corner;
angles in degrees with ``_deg`` suffixes) gives the arena, the landmarks (vertical cylinders),
the reference pair, the camera, the vision error bound and the trajectory::

    {
      "arena": {"width": 1.05, "height": 0.68},
      "landmarks": [{"name": "L1", "x": 0.375, "y": 0.55, "color": "red"},
                    {"name": "L7", "x": 0.9, "y": 0.2, "bands": ["magenta", "yellow"]}, ...],
      "reference": ["L1", "L2"],
      "camera": {"model": "unwrapped", "width": 255, "height": 176, "bearing_noise_deg": 1.0},
      "vision_error_deg": 3.0,
      "trajectory": {"start": [0.52, 0.34], "moves": 10, "distance": [0.10, 0.25], "seed": 7}
    }

A landmark has either ``color`` (one colour) or ``bands`` (two or more colours, top to bottom,
equal heights: a coded landmark). Several landmarks may share a colour or code, except the two
of the reference pair, which must each be the only one of their class.

Optional keys: ``description`` (text); landmark ``radius`` (m, default 0.01) and ``height``
(m, default 0.15); camera ``bearing_noise_deg`` (default 0), ``pixel_noise`` (grey-level std,
default 2) and ``lighting`` (bool, default true), and for ``"model": "pinhole"`` ``fov_deg``
(horizontal field of view, default 60) and ``distortion`` (``plumb_bob`` coefficients, default
none); ``robot.radius`` (m, default 0.03: the
robot keeps this far from walls); trajectory ``start`` may hold a third element, the start
heading in degrees; ``seed`` defaults to 0. ``moves`` is either a count of random moves (then
``distance`` = [min, max] m is required) or an explicit list ``[{"turn_deg": 40,
"distance": 0.2}, ...]``. Unknown keys are errors (they are usually typos).

Public API
----------
- :func:`load_scenario` (path) and :func:`scenario_from_dict` (decoded JSON) ->
  :class:`Scenario`; every problem is one :class:`~data_schemas.errors.ScenarioError` line
  naming the key.
- :func:`builtin_scenario` (``"paper"``, ``"paper_omni"``) and :data:`BUILTIN_SCENARIOS`.
- :class:`Scenario`: ``world()``, ``calibration()``, ``to_dict()``, ``with_seed(seed)``,
  ``landmark(name)``.
"""

from __future__ import annotations

import dataclasses
import difflib
import json
import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any, Literal

from data_schemas.calibration import (
    Calibration,
    PinholeCalibration,
    UnwrappedCalibration,
    default_omni,
)
from data_schemas.catalog import catalog_problem
from data_schemas.codec import loads, validate
from data_schemas.colors import appearance_problem
from data_schemas.errors import CalibrationError, ScenarioError, SchemaError
from data_schemas.inputs import read_text
from data_schemas.registry import schema_dict
from data_schemas.session import LandmarkSpec, shared_reference_problem
from recorder.moves import Move
from recorder.sim.world import Arena, Landmark, Pose, SimWorld

DEFAULT_LANDMARK_RADIUS_M = 0.01
#: Horizontal field of view of a simulated pinhole camera, degrees.
DEFAULT_PINHOLE_FOV_DEG = 60.0
DEFAULT_LANDMARK_HEIGHT_M = 0.15
DEFAULT_ROBOT_RADIUS_M = 0.03
DEFAULT_PIXEL_NOISE = 2.0
#: Moves keep the robot's edge this far from walls and landmark surfaces (m): room for
#: actuation noise.
CLEARANCE_M = 0.04

BUILTIN_SCENARIOS: tuple[str, ...] = ("paper", "paper_omni", "coded_3x2")


def _allowed_keys() -> dict[str, tuple[str, ...]]:
    """Allowed keys per object, read from the ``bslam.Scenario`` schema (checked before the
    schema itself, to give "did you mean" hints): "" is the top level, "landmarks[]" an item."""
    schema = schema_dict("bslam.Scenario")
    props = schema["properties"]
    moves = next(b for b in props["trajectory"]["properties"]["moves"]["oneOf"] if "items" in b)
    objects = {
        "": schema,
        "arena": props["arena"],
        "landmarks[]": props["landmarks"]["items"],
        "camera": props["camera"],
        "trajectory": props["trajectory"],
        "trajectory.moves[]": moves["items"],
        "robot": props["robot"],
    }
    return {name: tuple(obj["properties"]) for name, obj in objects.items()}


_KEYS = _allowed_keys()


@dataclass(frozen=True)
class CameraSpec:
    """The simulated camera.

    Attributes
    ----------
    model : {"unwrapped", "omni", "pinhole"}
    width, height : int
        Image size, pixels.
    fov_rad : float
        Pinhole only: horizontal field of view of the undistorted image (the focal length).
    distortion : tuple of float
        Pinhole only: ``plumb_bob`` coefficients (k1, k2, p1, p2[, k3]), or none.
    bearing_noise_rad : float
        Std of the Gaussian bearing noise (before truncation at the vision error bound).
    pixel_noise : float
        Std of the per-pixel noise, grey levels (0..255).
    lighting : bool
        Whether frames get lighting variation (global gain and a gradient).
    """

    model: Literal["unwrapped", "omni", "pinhole"]
    width: int
    height: int
    bearing_noise_rad: float = 0.0
    pixel_noise: float = DEFAULT_PIXEL_NOISE
    lighting: bool = True
    fov_rad: float = math.radians(DEFAULT_PINHOLE_FOV_DEG)
    distortion: tuple[float, ...] = ()


@dataclass(frozen=True)
class Trajectory:
    """Where the robot starts and how it moves.

    Exactly one of ``random_count`` and ``moves`` is set.

    Attributes
    ----------
    start_world : (x, y, heading)
        Start pose, m and rad, world frame.
    random_count : int or None
        Number of random moves.
    distance_range_m : (float, float) or None
        Range of random move distances, m.
    moves : tuple of Move or None
        Explicit moves.
    seed : int
        Seed of the random moves (and the default seed of the simulation).
    """

    start_world: Pose
    random_count: int | None = None
    distance_range_m: tuple[float, float] | None = None
    moves: tuple[Move, ...] | None = None
    seed: int = 0

    @property
    def n_moves(self) -> int:
        """Number of straight movements."""
        if self.moves is not None:
            return len(self.moves)
        assert self.random_count is not None
        return self.random_count


@dataclass(frozen=True)
class Scenario:
    """A validated simulation scenario (see the module docstring for the file format)."""

    arena: Arena
    landmarks: tuple[Landmark, ...]
    reference: tuple[str, str]
    camera: CameraSpec
    vision_error_rad: float
    trajectory: Trajectory
    robot_radius_m: float = DEFAULT_ROBOT_RADIUS_M
    description: str = ""

    def world(self) -> SimWorld:
        """The arena and landmarks as a :class:`~recorder.sim.world.SimWorld`."""
        return SimWorld(self.arena, self.landmarks)

    def landmark(self, name: str) -> Landmark:
        """The landmark called ``name`` (KeyError if absent)."""
        for lm in self.landmarks:
            if lm.name == name:
                return lm
        raise KeyError(name)

    def calibration(self) -> Calibration:
        """The camera calibration the simulator renders with."""
        cam = self.camera
        if cam.model == "unwrapped":
            return UnwrappedCalibration(cam.width, cam.height)
        if cam.model == "pinhole":
            return simulated_pinhole(cam.width, cam.height, cam.fov_rad, cam.distortion)
        return default_omni(cam.width, cam.height)

    def _pinhole_keys(self) -> dict[str, Any]:
        cam = self.camera
        if cam.model != "pinhole":
            return {}
        return {"fov_deg": _deg(cam.fov_rad), "distortion": list(cam.distortion)}

    def with_seed(self, seed: int) -> Scenario:
        """The same scenario with ``trajectory.seed`` replaced (``--seed`` on the CLI)."""
        return dataclasses.replace(
            self, trajectory=dataclasses.replace(self.trajectory, seed=int(seed))
        )

    def to_dict(self) -> dict[str, Any]:
        """The scenario as JSON (defaults filled in), valid against ``bslam.Scenario``."""
        traj = self.trajectory
        start = [traj.start_world[0], traj.start_world[1], _deg(traj.start_world[2])]
        traj_doc: dict[str, Any] = {"start": start, "seed": traj.seed}
        if traj.moves is not None:
            traj_doc["moves"] = [
                {"turn_deg": _deg(m.turn_rad), "distance": m.distance_m} for m in traj.moves
            ]
        else:
            traj_doc["moves"] = traj.random_count
            assert traj.distance_range_m is not None
            traj_doc["distance"] = list(traj.distance_range_m)
        doc: dict[str, Any] = {
            "arena": {"width": self.arena.width_m, "height": self.arena.height_m},
            "landmarks": [
                {
                    "name": lm.name,
                    "x": lm.x,
                    "y": lm.y,
                    **({"bands": list(lm.bands)} if lm.bands else {"color": lm.color}),
                    "radius": lm.radius_m,
                    "height": lm.height_m,
                }
                for lm in self.landmarks
            ],
            "reference": list(self.reference),
            "camera": {
                "model": self.camera.model,
                "width": self.camera.width,
                "height": self.camera.height,
                "bearing_noise_deg": _deg(self.camera.bearing_noise_rad),
                "pixel_noise": self.camera.pixel_noise,
                "lighting": self.camera.lighting,
                **self._pinhole_keys(),
            },
            "vision_error_deg": _deg(self.vision_error_rad),
            "trajectory": traj_doc,
            "robot": {"radius": self.robot_radius_m},
        }
        if self.description:
            doc["description"] = self.description
        return doc


def _deg(angle_rad: float) -> float:
    """Degrees for JSON, rounded so that a degree value survives the round trip exactly."""
    return round(math.degrees(angle_rad), 9)


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario file.

    Raises
    ------
    ScenarioError
        One line naming the file and the offending key.
    """
    p = Path(path)
    if not p.exists() and not p.is_symlink():
        raise ScenarioError(f"scenario file {str(p)!r} does not exist")
    text = read_text(p, what="scenario file", error=ScenarioError)
    doc = loads(text, what=f"scenario {p.name}", error=ScenarioError)
    return scenario_from_dict(doc, what=f"scenario {p.name}")


def scenario_named(name_or_path: str | Path) -> Scenario:
    """A built-in scenario (:data:`BUILTIN_SCENARIOS`) by name, else a scenario file.

    Raises
    ------
    ScenarioError
        Neither a built-in name nor a file (the close built-in names are suggested), or a file
        that is not a valid scenario.
    """
    if str(name_or_path) in BUILTIN_SCENARIOS:
        return builtin_scenario(str(name_or_path))
    if not Path(name_or_path).exists():
        close = difflib.get_close_matches(str(name_or_path), BUILTIN_SCENARIOS, n=2)
        hint = f"did you mean {' or '.join(repr(c) for c in close)}? " if close else ""
        raise ScenarioError(
            f"{str(name_or_path)!r} is neither a scenario file nor a built-in scenario; {hint}"
            f"the built-in ones: {', '.join(BUILTIN_SCENARIOS)}"
        )
    return load_scenario(name_or_path)


def builtin_scenario(name: str) -> Scenario:
    """A scenario shipped with bearing-slam (see :data:`BUILTIN_SCENARIOS`)."""
    if name not in BUILTIN_SCENARIOS:
        raise ScenarioError(
            f"unknown built-in scenario {name!r}; choose one of {', '.join(BUILTIN_SCENARIOS)}"
        )
    text = resources.files("recorder.sim").joinpath("scenarios", f"{name}.json").read_text()
    return scenario_from_dict(json.loads(text), what=f"built-in scenario {name!r}")


def scenario_from_dict(doc: Any, *, what: str = "scenario") -> Scenario:
    """Validate decoded scenario JSON and build a :class:`Scenario` (raise ScenarioError)."""
    if not isinstance(doc, dict):
        raise ScenarioError(f"{what}: must be a JSON object")
    _check_keys(doc, what)
    _check_appearance(doc, what)
    try:
        validate("bslam.Scenario", doc, what=what)
    except SchemaError as exc:
        raise ScenarioError(str(exc)) from None

    def fail(key: str, message: str) -> ScenarioError:
        return ScenarioError(f"{what}: key {key!r}: {message}")

    arena = Arena(float(doc["arena"]["width"]), float(doc["arena"]["height"]))
    ref = doc["reference"]
    problem = catalog_problem([d["name"] for d in doc["landmarks"]], ref)
    if problem is not None:
        raise fail(*problem)
    landmarks: list[Landmark] = []
    for i, d in enumerate(doc["landmarks"]):
        key = f"landmarks[{i}]"
        lm = Landmark(
            d["name"],
            float(d["x"]),
            float(d["y"]),
            d.get("color"),
            float(d.get("radius", DEFAULT_LANDMARK_RADIUS_M)),
            float(d.get("height", DEFAULT_LANDMARK_HEIGHT_M)),
            tuple(d.get("bands", ())),
        )
        if not (lm.radius_m <= lm.x <= arena.width_m - lm.radius_m) or not (
            lm.radius_m <= lm.y <= arena.height_m - lm.radius_m
        ):
            raise fail(
                key,
                f"landmark {lm.name} at ({lm.x:g}, {lm.y:g}) m is outside the "
                f"{arena.width_m:g} x {arena.height_m:g} m arena",
            )
        for other in landmarks:
            if math.hypot(lm.x - other.x, lm.y - other.y) < lm.radius_m + other.radius_m:
                raise fail(
                    key,
                    f"landmark {lm.name} at ({lm.x:g}, {lm.y:g}) m overlaps landmark "
                    f"{other.name} at ({other.x:g}, {other.y:g}) m; move one of them apart",
                )
        landmarks.append(lm)

    shared = shared_reference_problem(
        [LandmarkSpec(lm.name, lm.color, bands=lm.bands) for lm in landmarks], ref
    )
    if shared:
        raise fail("reference", shared)

    cam = doc["camera"]
    camera = CameraSpec(
        cam["model"],
        int(cam["width"]),
        int(cam["height"]),
        math.radians(float(cam.get("bearing_noise_deg", 0.0))),
        float(cam.get("pixel_noise", DEFAULT_PIXEL_NOISE)),
        bool(cam.get("lighting", True)),
        math.radians(float(cam.get("fov_deg", DEFAULT_PINHOLE_FOV_DEG))),
        tuple(float(v) for v in cam.get("distortion", ())),
    )
    if camera.model != "pinhole" and ({"fov_deg", "distortion"} & set(cam)):
        raise fail("camera", "fov_deg and distortion are for a pinhole camera (model 'pinhole')")
    if camera.model == "pinhole":
        try:
            simulated_pinhole(camera.width, camera.height, camera.fov_rad, camera.distortion)
        except CalibrationError as exc:
            raise fail("camera", str(exc)) from None
    robot_radius = float(doc.get("robot", {}).get("radius", DEFAULT_ROBOT_RADIUS_M))

    t = doc["trajectory"]
    start = t["start"]
    start_world: Pose = (
        float(start[0]),
        float(start[1]),
        math.radians(float(start[2])) if len(start) > 2 else 0.0,
    )
    if not arena.contains(start_world[0], start_world[1], robot_radius):
        raise fail(
            "trajectory.start",
            f"({start_world[0]:g}, {start_world[1]:g}) m is outside the "
            f"{arena.width_m:g} x {arena.height_m:g} m arena (or closer to a wall than the "
            f"robot radius {robot_radius:g} m)",
        )
    for lm in landmarks:
        if math.hypot(lm.x - start_world[0], lm.y - start_world[1]) < lm.radius_m + robot_radius:
            raise fail(
                "trajectory.start",
                f"({start_world[0]:g}, {start_world[1]:g}) m puts the robot on landmark {lm.name}",
            )
    seed = int(t.get("seed", 0))
    if isinstance(t["moves"], int):
        if "distance" not in t:
            raise fail("trajectory.distance", "random moves need a distance range [min, max] (m)")
        lo, hi = (float(v) for v in t["distance"])
        if lo > hi:
            raise fail(
                "trajectory.distance", f"range is inverted: [{lo:g}, {hi:g}]; give [min, max]"
            )
        trajectory = Trajectory(start_world, int(t["moves"]), (lo, hi), None, seed)
    else:
        if "distance" in t:
            raise fail("trajectory.distance", "only used with random moves (moves is a list here)")
        moves = tuple(
            Move(math.radians(float(m["turn_deg"])), float(m["distance"])) for m in t["moves"]
        )
        trajectory = Trajectory(start_world, None, None, moves, seed)

    scenario = Scenario(
        arena,
        tuple(landmarks),
        (ref[0], ref[1]),
        camera,
        math.radians(float(doc["vision_error_deg"])),
        trajectory,
        robot_radius,
        str(doc.get("description", "")),
    )
    if trajectory.moves is not None:
        _check_explicit_moves(scenario, fail)
    return scenario


def _check_explicit_moves(scenario: Scenario, fail: Any) -> None:
    """Dead-reckon the explicit moves from the start pose; reject the first unsafe one."""
    world = scenario.world()
    x, y, h = scenario.trajectory.start_world
    assert scenario.trajectory.moves is not None
    for i, m in enumerate(scenario.trajectory.moves):
        problem = world.move_problem(
            (x, y, h),
            m.turn_rad,
            m.distance_m,
            robot_radius_m=scenario.robot_radius_m,
            clearance_m=CLEARANCE_M,
        )
        if problem is not None:
            raise fail(
                f"trajectory.moves[{i}]",
                f"turn {math.degrees(m.turn_rad):g} deg then {m.distance_m:g} m from "
                f"({x:.3f}, {y:.3f}) m {problem}",
            )
        h += m.turn_rad
        x, y = x + m.distance_m * math.cos(h), y + m.distance_m * math.sin(h)


def _check_appearance(doc: dict[str, Any], what: str) -> None:
    """Each landmark has either ``color`` or ``bands`` (adjacent bands differ)."""
    landmarks = doc.get("landmarks")
    for i, lm in enumerate(landmarks if isinstance(landmarks, list) else []):
        problem = appearance_problem(lm) if isinstance(lm, dict) else None
        if problem:
            raise ScenarioError(f"{what}: key 'landmarks[{i}]': {problem}")


def _check_keys(doc: dict[str, Any], what: str) -> None:
    """Reject unknown keys (with a 'did you mean' hint) in the top level and known objects."""

    def check(obj: Any, allowed_key: str, where: str) -> None:
        if not isinstance(obj, dict):
            return  # the schema reports the wrong type
        allowed = _KEYS[allowed_key]
        for key in obj:
            if key not in allowed:
                close = difflib.get_close_matches(key, allowed, n=1)
                hint = f"; did you mean {close[0]!r}?" if close else ""
                full = f"{where}.{key}" if where else key
                raise ScenarioError(
                    f"{what}: unknown key {full!r}{hint} (allowed: {', '.join(allowed)})"
                )

    check(doc, "", "")
    for name in ("arena", "camera", "trajectory", "robot"):
        check(doc.get(name), name, name)
    landmarks = doc.get("landmarks")
    if isinstance(landmarks, list):
        for i, lm in enumerate(landmarks):
            check(lm, "landmarks[]", f"landmarks[{i}]")
    traj = doc.get("trajectory")
    moves = traj.get("moves") if isinstance(traj, dict) else None
    if isinstance(moves, list):
        for i, m in enumerate(moves):
            check(m, "trajectory.moves[]", f"trajectory.moves[{i}]")


def simulated_pinhole(
    width: int, height: int, fov_rad: float, distortion: tuple[float, ...] = ()
) -> PinholeCalibration:
    """The simulator's pinhole camera: square pixels, centred, looking forward, ``fov_rad`` wide
    (undistorted), ``plumb_bob`` distortion ``distortion``; raise CalibrationError."""
    fx = 0.5 * width / math.tan(0.5 * fov_rad)
    return PinholeCalibration(
        width,
        height,
        fx=fx,
        fy=fx,
        cx=0.5 * width - 0.5,
        cy=0.5 * height - 0.5,
        distortion=distortion,
        distortion_model="plumb_bob",
    )
