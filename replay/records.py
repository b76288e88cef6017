"""Typed results of the offline stages, as sinks receive them.

The runner (:mod:`replay.stages`) turns a log into a stream of these records; sinks (summary,
derived MCAP, Rerun) only read them. Arrays are plain numpy with frame and unit in the name, so
a sink never needs the estimator's internals.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, cast, get_args

import numpy as np
from numpy.typing import NDArray

from data_schemas.errors import EstimationError
from data_schemas.session import Session
from pipeline.association.final import STATUSES, FinalDetection
from pipeline.bearings import Detection
from pipeline.estimators import ESTIMATORS
from pipeline.priors import PriorName
from pipeline.slam import MovementStatus, Placement
from replay import defaults
from replay.truth import Truth

#: the prior names, in the order of ``pipeline.priors.PriorName``
PRIORS: tuple[PriorName, ...] = get_args(PriorName)


@dataclass(frozen=True)
class MethodConfig:
    """Estimator settings of one run (``bslam process`` options; defaults: ``replay.defaults``).

    Attributes
    ----------
    prior : {"impartial", "gaussian", "mixture"}
        Density of one observation (the paper's impartial PDF or a baseline).
    n_r, n_l : int
        Particles per landmark in FR (after one movement) and in FL (the belief).
    seed : int
        Seed of the run's ``numpy.random.Generator``.
    estimator : {"joint", "paper"}
        Which estimator makes the map (:mod:`pipeline.estimators`); the particle settings are
        the paper filter's (the joint estimator's initializer).
    turn_prior_deg : float or None
        Joint estimator: std of a prior on each turn in place from the commanded turn
        (``/robot/movement``); None leaves the turns free.
    distance_prior : float or None
        Joint estimator: relative std of a prior on each movement's length from its driven
        distance (odometry, else the commanded distance); None leaves the lengths free.
        An expected summary without it was made with the lengths free (``replay.regress``).
    keyframe_distance_m, keyframe_turn_deg : float or None
        Driving logs: path length (m) and turning (deg) between keyframes (None: the driving
        estimator's defaults, :mod:`pipeline.driving.keyframes`).
    odometry_std_per_m, odometry_heading_std_per_rad : float or None
        Driving logs: the wheel model's position std per metre of path and heading std per
        radian turned (None: :mod:`pipeline.driving.odometry`'s defaults).
    window : int
        Joint estimator: movements kept in the graph, older ones marginalized
        (:mod:`pipeline.joint.window`); 0 keeps every movement.
    keyframe_window : int
        Driving logs: keyframes kept in iSAM2, older ones marginalized
        (:mod:`pipeline.driving.lag`); 0 keeps every keyframe.
    """

    prior: str = defaults.PRIOR
    n_r: int = defaults.N_R
    n_l: int = defaults.N_L
    seed: int = defaults.SEED
    estimator: str = defaults.ESTIMATOR
    turn_prior_deg: float | None = defaults.TURN_PRIOR_DEG
    distance_prior: float | None = defaults.DISTANCE_PRIOR_REL
    keyframe_distance_m: float | None = None
    keyframe_turn_deg: float | None = None
    odometry_std_per_m: float | None = None
    odometry_heading_std_per_rad: float | None = None
    window: int = defaults.JOINT_WINDOW
    keyframe_window: int = defaults.KEYFRAME_WINDOW

    def __post_init__(self) -> None:
        if self.prior not in PRIORS:
            raise EstimationError(f"unknown prior {self.prior!r}; use one of {', '.join(PRIORS)}")
        if self.estimator not in ESTIMATORS:
            raise EstimationError(
                f"unknown estimator {self.estimator!r}; use one of {', '.join(ESTIMATORS)}"
            )
        if self.turn_prior_deg is not None and not self.turn_prior_deg > 0.0:
            raise EstimationError(f"turn prior std must be > 0 deg, got {self.turn_prior_deg}")
        if self.distance_prior is not None and not self.distance_prior > 0.0:
            raise EstimationError(f"distance prior std must be > 0, got {self.distance_prior}")
        for what, v in (
            ("keyframe distance", self.keyframe_distance_m),
            ("keyframe turn", self.keyframe_turn_deg),
            ("odometry std per metre", self.odometry_std_per_m),
            ("odometry heading std per radian", self.odometry_heading_std_per_rad),
        ):
            if v is not None and not (math.isfinite(v) and v > 0.0):
                raise EstimationError(f"{what} must be a finite number > 0, got {v}")
        for what, n in (("window", self.window), ("keyframe window", self.keyframe_window)):
            if n < 0:
                raise EstimationError(f"{what} must be a count >= 0 (0: keep all), got {n}")

    @property
    def prior_name(self) -> PriorName:
        """The prior, typed for :mod:`pipeline`."""
        return cast(PriorName, self.prior)

    def summary(self, vision_error_rad: float) -> dict[str, Any]:
        """The summary's ``method`` block."""
        out: dict[str, Any] = {
            "estimator": self.estimator,
            "prior": self.prior,
            "n_r": self.n_r,
            "n_l": self.n_l,
            "vision_error_deg": round(float(np.degrees(vision_error_rad)), 9),
            "seed": self.seed,
        }
        if self.estimator == "joint" and self.turn_prior_deg is not None:
            out["turn_prior_deg"] = self.turn_prior_deg
        if self.estimator == "joint" and self.distance_prior is not None:
            out["distance_prior"] = self.distance_prior
        if self.estimator == "joint" and self.window != defaults.JOINT_WINDOW:
            out["window"] = self.window
        return out


@dataclass(frozen=True)
class FrameRecord:
    """Bearings of one decoded frame.

    Attributes
    ----------
    timestamp_ns : int
        The frame's sensor time stamp.
    log_time_ns : int
        When the recorder wrote it.
    keyframe : (index, phase) or None
        The movement keyframe this frame is, if any.
    detections : dict name -> Detection
        Every catalog landmark, in catalog order.
    image_bgr : (H, W, 3) uint8 or None
        The decoded frame, kept only when a sink asked for images.
    masks : dict name -> (H, W) bool, or None
        Colour masks, kept only when a sink asked for them.
    png : bytes or None
        The frame's PNG file as logged (None for raw frames), kept with ``image_bgr`` so a sink
        can pass the frame on without encoding it again.
    """

    timestamp_ns: int
    log_time_ns: int
    keyframe: tuple[int, str] | None
    detections: Mapping[str, Detection]
    image_bgr: NDArray[np.uint8] | None = None
    masks: Mapping[str, NDArray[np.bool_]] | None = None
    png: bytes | None = None


@dataclass(frozen=True)
class EstimateRecord:
    """One landmark's estimate in FL.

    Attributes
    ----------
    mean_fl : (2,) float
        Particle mean, FL (unit |L1 L2|).
    cov_fl : (2, 2) float
        Particle covariance, FL.
    ellipse80_fl : (k, 2) float
        Closed outline of the 80% credible region, FL.
    """

    mean_fl: NDArray[np.float64]
    cov_fl: NDArray[np.float64]
    ellipse80_fl: NDArray[np.float64]


@dataclass(frozen=True)
class MovementRecord:
    """What one straight movement produced (or why it was skipped).

    Attributes
    ----------
    index : int
        Movement index.
    timestamp_ns, log_time_ns : int
        Of the end keyframe (or of the last frame seen when it is missing).
    status : str
        ``"ok"`` or ``"skipped: <reason>"``.
    bearings_rad : dict name -> (start, end)
        Keyframe bearings used (None where not visible), every catalog landmark.
    skipped_landmarks : dict name -> reason
        Landmarks this movement could not initialise (not visible, degenerate geometry).
    cones_fr : dict name -> (cone at O1, cone at O2)
        Vision cone polygons (k, 2) in FR.
    particles_fr : dict name -> (n_r, 2)
        Landmark particles in FR (O1 = (0, 0), O2 = (1, 0)).
    particles_fl : dict name -> (n_l, 2)
        The belief in FL after this movement (every landmark seen so far).
    o1_fl, o2_fl : (n, 2) or None
        This movement's observation points in FL.
    estimates : dict name -> EstimateRecord
        The map after this movement.
    truth_o1_world, truth_o2_world : (2,) or None
        Simulated logs: the true keyframe positions (m, world).
    placement : Placement
        Joint estimator: ``REFERENCE_PAIR`` or ``RESECTION`` for a movement in the map; the
        driving estimator: ``ODOMETRY``; ``NONE`` otherwise (and always for the paper's filter).
    residuals_rad : dict name -> (at O1, at O2)
        Joint estimator: this movement's bearing residuals under the map after it.
    bearing_noise_rad : float or None
        Joint estimator: bearing noise std estimated from every residual of the map.
    divergence : str
        Joint estimator: why the map was re-initialized from the particles, if it was.
    solved_again : str
        Joint estimator: why the map was found stuck and solved again from its whole record,
        if it was.
    map_unit_m : float or None
        Joint estimator with the distance prior: the map's unit |L1 L2| in metres, estimated
        from the driven distances.
    ambiguous_landmarks : dict key -> reason
        What association left unresolved in this movement (a detection of a shared class that
        no landmark or several explain, a movement that could not be placed): never guessed.
        Without association (keyframe missing) the catalog landmarks of shared classes.
    not_visible : dict key -> reason
        Named landmarks of shared classes predicted at a keyframe (``red#1@O2``) but not
        detected there (hidden behind another, out of range).
    named_landmarks : list of str
        Landmarks of shared classes named with this movement (confirmed hypotheses).
    named_from : dict name -> list of (movement, end, bearing_rad)
        The landmarks named with this movement: the keyframe detections each was named from
        (``end`` 0 at O1, 1 at O2; this movement's included), which the estimator takes as its
        bearings from then on.
    doubtful_landmarks : dict name -> reason or None
        Named landmarks of shared classes whose predictions since their naming were too rarely
        seen, or whose bearings in the map scatter too widely (:mod:`pipeline.association.support`);
        None where association did not run.
    unconfirmed_landmarks : dict name -> reason or None
        Named landmarks of shared classes, not doubtful, seen at too few keyframes since their
        naming to confirm the name; None where association did not run.
    also_placed : tuple of int
        Joint estimator: earlier movements that had to wait and entered the map with this one.
    rays_fl : dict name -> (2, 2) float
        Driving logs: each bearing of the keyframe as a segment in FL from where it was taken.
    """

    index: int
    timestamp_ns: int
    log_time_ns: int
    status: str
    bearings_rad: Mapping[str, tuple[float | None, float | None]]
    skipped_landmarks: Mapping[str, str] = field(default_factory=dict)
    cones_fr: Mapping[str, tuple[NDArray[np.float64], NDArray[np.float64]]] = field(
        default_factory=dict
    )
    particles_fr: Mapping[str, NDArray[np.float64]] = field(default_factory=dict)
    particles_fl: Mapping[str, NDArray[np.float64]] = field(default_factory=dict)
    o1_fl: NDArray[np.float64] | None = None
    o2_fl: NDArray[np.float64] | None = None
    estimates: Mapping[str, EstimateRecord] = field(default_factory=dict)
    truth_o1_world: NDArray[np.float64] | None = None
    truth_o2_world: NDArray[np.float64] | None = None
    placement: Placement = Placement.NONE
    residuals_rad: Mapping[str, tuple[float | None, float | None]] = field(default_factory=dict)
    bearing_noise_rad: float | None = None
    divergence: str = ""
    solved_again: str = ""
    map_unit_m: float | None = None
    ambiguous_landmarks: Mapping[str, str] = field(default_factory=dict)
    also_placed: tuple[int, ...] = ()
    not_visible: Mapping[str, str] = field(default_factory=dict)
    named_landmarks: Sequence[str] = ()
    named_from: Mapping[str, Sequence[tuple[int, int, float]]] = field(default_factory=dict)
    doubtful_landmarks: Mapping[str, str] | None = None
    unconfirmed_landmarks: Mapping[str, str] | None = None
    rays_fl: Mapping[str, NDArray[np.float64]] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """True if the movement updated the map."""
        return self.status == MovementStatus.OK


@dataclass(frozen=True)
class AssociationRecord:
    """Every keyframe detection of a shared class associated with the final map, once the
    log is processed (landmarks that look alike, joint estimator;
    :func:`pipeline.association.final.associate_final`).

    Attributes
    ----------
    timestamp_ns, log_time_ns : int
        Of the last frame processed.
    detections : list of FinalDetection
        Every keyframe detection of a shared class, its name (if any) and status.
    reports : dict label -> str
        Classes whose detections the final map leaves unexplained too often (every name
        given or not) (:func:`pipeline.association.final.missing_reports`).
    retracted : dict name -> str
        Names under suspicion (doubtful, or given few of their predicted detections) taken
        back once the log was processed and given anew where the final map's unexplained
        detections point, with why.
    estimates : dict name -> EstimateRecord, or None
        The map once the log is processed (association and map made to agree, names retracted
        or given then); None: the last movement's map stands.
    placed_by_matching : list of int
        Movements the map left out or held misplaced, placed for this association by matching
        their detections with the final map (:func:`pipeline.association.match.place_left_out`,
        :func:`pipeline.association.match.misplaced`).
    named_at_end : dict name -> str
        Free names given once the log was processed to landmarks the final map's unexplained
        detections point at, with why (``estimates`` is then the map with them).
    weak : dict name -> str
        Names the final association supports weakly, with why
        (:func:`pipeline.association.final.weak_names`).
    """

    timestamp_ns: int
    log_time_ns: int
    detections: Sequence[FinalDetection]
    reports: Mapping[str, str] = field(default_factory=dict)
    retracted: Mapping[str, str] = field(default_factory=dict)
    estimates: Mapping[str, EstimateRecord] | None = None
    placed_by_matching: Sequence[int] = ()
    named_at_end: Mapping[str, str] = field(default_factory=dict)
    weak: Mapping[str, str] = field(default_factory=dict)

    def counts(self) -> dict[str, dict[str, int]]:
        """Per class: ``detections`` and how many of them are in each status (``named``,
        ``contested``, ``unexplained``, ``not placed``)."""
        out: dict[str, dict[str, int]] = {}
        for d in self.detections:
            c = out.setdefault(d.label, {"detections": 0, **{str(s): 0 for s in STATUSES}})
            c["detections"] += 1
            c[d.status] += 1
        return out

    def text(self) -> str:
        """One line per class: how many detections the final map names, and the rest."""
        parts = []
        for label, c in self.counts().items():
            rest = ", ".join(f"{c[s]} {s}" for s in STATUSES[1:] if c[s])
            parts.append(
                f"{label}: {c['named']} of {c['detections']} detections named"
                + (f" ({rest})" if rest else "")
            )
        text = "with the final map, " + ("; ".join(parts) or "no detections to associate")
        if self.placed_by_matching:
            moves = ", ".join(str(m) for m in self.placed_by_matching)
            text += f" (movement(s) {moves}, left out of the map or misplaced, placed by matching)"
        return text


@dataclass(frozen=True)
class RunInfo:
    """What every sink learns before the first record.

    Attributes
    ----------
    log_name : str
        The log's file name (for messages and the summary).
    session : Session
        The log's session metadata.
    method : MethodConfig
        Estimator settings.
    truth : Truth or None
        Simulation truth, for simulated logs (an imported log's outside reference).
    driving : bool
        A driving log (bearings and odometry): each movement record is a keyframe.
    """

    log_name: str
    session: Session
    method: MethodConfig
    truth: Truth | None
    driving: bool = False

    @property
    def estimator(self) -> str:
        """The estimator that makes the map: ``driving`` for a driving log, else the method's."""
        return "driving" if self.driving else self.method.estimator


class Sink(Protocol):
    """Receives the stages' results of one log, in log-time order.

    ``wants_all_frames``: the runner decodes every frame (not only keyframes) for this sink.
    ``wants_images``: frames carry ``image_bgr``, ``masks`` and (PNG frames) ``png``.
    """

    wants_all_frames: bool
    wants_images: bool

    def start(self, run: RunInfo) -> None:
        """Called once, before any record."""

    def frame(self, frame: FrameRecord) -> None:
        """One decoded frame's bearings."""

    def movement(self, record: MovementRecord) -> None:
        """One movement, in index order, after its end keyframe."""

    def association(self, record: AssociationRecord) -> None:
        """Once the last movement is processed, with landmarks that look alike: every
        keyframe detection associated with the final map."""

    def finish(self) -> None:
        """Called once at the end (also after an error, to release files)."""
