"""The public estimator: bearings of one straight movement in, particle sets and estimates out.

Example
-------
>>> import numpy as np
>>> from pipeline import BearingSlam, MovementObservation
>>> slam = BearingSlam(["L1", "L2", "L3"], ("L1", "L2"), vision_error_rad=np.radians(3),
...                    rng=np.random.default_rng(0))
>>> res = slam.process_movement(MovementObservation(0, {"L1": 1.2, "L2": 0.9, "L3": 2.5},
...                                                 {"L1": 1.5, "L2": 1.3, "L3": 2.7}))
>>> res.status, sorted(res.estimates)
('ok', ['L3'])
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from enum import StrEnum, unique
from functools import partial
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from data_schemas.catalog import catalog_problem
from data_schemas.errors import EstimationError
from pipeline.cones import (
    O1_FR,
    O2_FR,
    ConeIntersection,
    Degenerate,
    intersect_cones,
    vision_cone_polygon,
)
from pipeline.estimate import LandmarkEstimate
from pipeline.frame_change import FrameChange, change_frame
from pipeline.fusion import PAPER_N_L, PAPER_N_R, LikelihoodUpdate, fuse, fuse_likelihood
from pipeline.init_fr import initialize_fr, sample_fr_posterior
from pipeline.likelihood import N_FRAMES, FrameLikelihood
from pipeline.priors import R_MAX_FR, R_MIN_FR, ImpartialPrior, PriorName, make_prior
from pipeline.resample import systematic_resample

Fusion = Literal["likelihood", "product"]

#: Default FR particles per reference landmark for the frame marginalisation.
N_FRAME_POOL = 1024


@unique
class MovementStatus(StrEnum):
    """The kind of a movement's status: used (``"ok"``), or skipped with its reason
    (``"skipped: <reason>"``, :func:`skipped`)."""

    OK = "ok"
    SKIPPED = "skipped"


def skipped(reason: str) -> str:
    """The status of a movement skipped for ``reason``: ``"skipped: <reason>"``."""
    return f"{MovementStatus.SKIPPED}: {reason}"


@unique
class Placement(StrEnum):
    """How a movement's keyframes entered the map (the summary's ``placement``)."""

    #: not in the map, or placed by the paper's filter (which says nothing)
    NONE = ""
    #: from the reference pair's bearings (the paper's filter could use the movement too)
    REFERENCE_PAIR = "reference pair"
    #: against the landmarks already in the map (joint estimator)
    RESECTION = "resection"
    #: from wheel odometry (the driving estimator's keyframes)
    ODOMETRY = "odometry"


@dataclass(frozen=True)
class MovementObservation:
    """Bearings of one straight movement (robot frame, rad, CCW, 0 = forward).

    A landmark missing from either mapping is not used for this movement. ``turn_rad`` is the
    commanded turn in place before the movement (CCW, ``/robot/movement``) and ``distance_m`` the
    straight distance driven (metres: the wheel odometry of ``/robot/odometry`` when logged, else
    the commanded distance), if known; the paper's filter uses neither.
    """

    index: int
    bearings_o1_rad: Mapping[str, float]
    bearings_o2_rad: Mapping[str, float]
    turn_rad: float | None = None
    distance_m: float | None = None


def _empty() -> NDArray[np.float64]:
    return np.zeros((0, 2))


@dataclass
class MovementResult:
    """Everything one movement produced (for display, logging and tests).

    Attributes
    ----------
    index : int
        The movement's index.
    status : str
        ``"ok"`` or ``"skipped: <reason>"`` (state unchanged).
    skipped_landmarks : dict of name -> reason
        Landmarks without an FR particle set this movement (not seen, degenerate cones, ...).
    fused : list of str
        Landmarks whose belief this movement changed (started or updated). With
        ``fusion="likelihood"`` a landmark with degenerate cones is still fused once it has a
        belief: its bearings' likelihood needs no bounded ``A_i``.
    defensive : list of str
        Landmarks of ``fused`` whose likelihood update used the defensive mixture proposal
        (:func:`pipeline.fusion.fuse_likelihood`: the belief alone was a poor proposal).
    cones_fr : dict of name -> (cone at O1, cone at O2), polygons (k, 2) FR
    particles_fr : dict of name -> (n_r, 2) FR, reference pair included
    particles_fl : dict of name -> (n_l, 2) FL, this movement's ``p_t`` (non-reference)
    o1_fl, o2_fl : ndarray (m, 2)
        Particles of the observation points in FL.
    belief_fl : dict of name -> (n_l, 2) FL
        Fused belief after this movement (all landmarks known so far).
    estimates : dict of name -> LandmarkEstimate
    """

    index: int
    status: str
    skipped_landmarks: dict[str, str] = field(default_factory=dict)
    fused: list[str] = field(default_factory=list)
    defensive: list[str] = field(default_factory=list)
    cones_fr: dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]] = field(
        default_factory=dict
    )
    particles_fr: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    particles_fl: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    o1_fl: NDArray[np.float64] = field(default_factory=_empty)
    o2_fl: NDArray[np.float64] = field(default_factory=_empty)
    belief_fl: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    estimates: dict[str, LandmarkEstimate] = field(default_factory=dict)


class BearingSlam:
    """Sequential bearing-only SLAM with the impartial PDF (or a baseline prior).

    Parameters
    ----------
    landmarks : sequence of str
        Landmark names (the catalog).
    reference : (str, str)
        Reference pair: L1 -> (0, 0), L2 -> (1, 0) in FL.
    vision_error_rad : float
        Bound eps on the bearing error.
    prior : {"impartial", "gaussian", "mixture"}
        Single-bearing prior used to weight the cone intersection.
    n_r : int
        Particles per landmark in FR (default: the paper's).
    n_l : int
        Particles per landmark in FL (default: the paper's).
    frame_change : {"sampled", "exact"}
        O(n_l) random triples (default: as accurate, far faster) or the paper's enumeration.
    rng : numpy.random.Generator
    r_min, r_max : float
        Range bounds of the vision cones in FR units (movement length = 1).
    fusion : {"likelihood", "product"}
        ``"likelihood"`` (default): fuse each movement's bearing likelihood, marginalised over
        the movement's frame (prior counted once); ``"product"``: the paper's product of the
        belief with each movement's FL set (counts the range prior at every movement).
    bearing_sigma_frac : float
        Std of the Gaussian bearing-error density ``g`` as a fraction of ``eps`` (truncated to
        ``[-eps, eps]``); default 0.5 (the bound at two standard deviations).
    n_proposal : int, optional
        Proposal draws per likelihood fusion (default 16 ``n_l``).
    n_frames : int
        Frame pairs averaged per proposal in the likelihood (default 16).
    n_frame_pool : int
        FR particles of each reference landmark that resolve the movement's frame in the
        likelihood (default 1024; drawn by :func:`pipeline.init_fr.sample_fr_posterior`).
    """

    def __init__(
        self,
        landmarks: Sequence[str],
        reference: tuple[str, str],
        *,
        vision_error_rad: float,
        prior: PriorName = "impartial",
        n_r: int = PAPER_N_R,
        n_l: int = PAPER_N_L,
        frame_change: FrameChange = "sampled",
        rng: np.random.Generator,
        r_min: float = R_MIN_FR,
        r_max: float = R_MAX_FR,
        fusion: Fusion = "likelihood",
        bearing_sigma_frac: float = 0.5,
        n_proposal: int | None = None,
        n_frames: int = N_FRAMES,
        n_frame_pool: int = N_FRAME_POOL,
    ) -> None:
        names = list(landmarks)
        problem = catalog_problem(names, reference)
        if problem is not None:
            raise EstimationError(f"{problem[0]}: {problem[1]}")
        if n_r < 2 or n_l < 2:
            raise EstimationError(f"need n_r >= 2 and n_l >= 2, got n_r={n_r}, n_l={n_l}")
        if frame_change not in ("sampled", "exact"):
            raise EstimationError(
                f"frame_change must be 'sampled' or 'exact', got {frame_change!r}"
            )
        if fusion not in ("likelihood", "product"):
            raise EstimationError(f"fusion must be 'likelihood' or 'product', got {fusion!r}")
        if not bearing_sigma_frac > 0.0:
            raise EstimationError(f"bearing_sigma_frac must be > 0, got {bearing_sigma_frac}")
        if min(n_frames, n_frame_pool, n_l if n_proposal is None else n_proposal) < 1:
            raise EstimationError(
                f"need n_frames, n_frame_pool, n_proposal >= 1, got {n_frames}, "
                f"{n_frame_pool}, {n_proposal}"
            )
        self.landmarks = names
        self.reference = reference
        self.eps_rad = float(vision_error_rad)
        self.prior = make_prior(prior, self.eps_rad, r_min, r_max, sigma_frac=bearing_sigma_frac)
        self.noise = ImpartialPrior(self.eps_rad, r_min, r_max, sigma_frac=bearing_sigma_frac)
        self.fusion: Fusion = fusion
        self.n_proposal = n_proposal
        self.n_frames = n_frames
        self.n_frame_pool = n_frame_pool
        self.n_r = n_r
        self.n_l = n_l
        self.frame_change: FrameChange = frame_change
        self.rng = rng
        self._belief: dict[str, NDArray[np.float64]] = {}
        # the same beliefs as weighted sets (all proposals of the last likelihood fusion)
        self._weighted: dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]] = {}
        self._trajectory: list[tuple[NDArray[np.float64], NDArray[np.float64]]] = []
        self.used_movements: list[int] = []

    def _initialize(
        self, obs: MovementObservation, res: MovementResult, regions: dict[str, ConeIntersection]
    ) -> dict[str, NDArray[np.float64]]:
        """FR particle sets of every usable landmark; fills ``regions`` with their ``A_i``."""
        pr = self.prior
        out: dict[str, NDArray[np.float64]] = {}
        for name in sorted(set(obs.bearings_o1_rad) | set(obs.bearings_o2_rad)):
            if name not in self.landmarks:
                res.skipped_landmarks[name] = "not in the landmark catalog"
        for name in self.landmarks:
            b1 = obs.bearings_o1_rad.get(name)
            b2 = obs.bearings_o2_rad.get(name)
            if b1 is None or b2 is None:
                where = "O1 and O2" if b1 is None and b2 is None else ("O1" if b1 is None else "O2")
                res.skipped_landmarks[name] = f"not seen at {where}"
                continue
            b1, b2 = float(b1), float(b2)
            if math.isfinite(b1) and math.isfinite(b2):
                res.cones_fr[name] = (
                    vision_cone_polygon(O1_FR, b1, self.eps_rad, pr.r_min, pr.r_max),
                    vision_cone_polygon(O2_FR, b2, self.eps_rad, pr.r_min, pr.r_max),
                )
            region = intersect_cones(b1, b2, self.eps_rad, pr.r_min, pr.r_max)
            if isinstance(region, Degenerate):
                res.skipped_landmarks[name] = region.reason
                continue
            s = initialize_fr(region, pr, self.n_r, self.rng)
            if isinstance(s, Degenerate):
                res.skipped_landmarks[name] = s.reason
                continue
            out[name] = s
            regions[name] = region
        return out

    def _frame(self, regions: dict[str, ConeIntersection]) -> FrameLikelihood | None:
        """The movement's frame for the likelihood (reference pair, n_frame_pool FR particles)."""
        out = []
        for ref in self.reference:
            s = sample_fr_posterior(
                regions[ref], self.prior, self.noise, self.n_frame_pool, self.rng
            )
            if isinstance(s, Degenerate):
                return None
            out.append(s)
        return FrameLikelihood(out[0], out[1], self.noise, n_frames=self.n_frames)

    def _fuse_likelihood(
        self,
        prev: tuple[NDArray[np.float64], NDArray[np.float64]],
        frame: FrameLikelihood,
        b1: float,
        b2: float,
        new_fl: NDArray[np.float64] | None,
    ) -> LikelihoodUpdate | None:
        lik = partial(frame, bearing_o1_rad=b1, bearing_o2_rad=b2, rng=self.rng)
        return fuse_likelihood(
            prev[0],
            lik,
            self.n_l,
            self.rng,
            prev_weights=prev[1],
            new_fl=new_fl,
            n_proposal=self.n_proposal,
        )

    def process_movement(self, obs: MovementObservation) -> MovementResult:
        """Initialize every visible landmark in FR, move to FL and fuse into the belief.

        A movement whose reference landmarks are missing or degenerate gets status
        ``"skipped: <reason>"`` and leaves the state unchanged.
        """
        res = MovementResult(obs.index, MovementStatus.OK)
        regions: dict[str, ConeIntersection] = {}
        sets_fr = self._initialize(obs, res, regions)
        res.particles_fr = sets_fr
        for ref in self.reference:
            if ref not in sets_fr:
                res.status = skipped(f"reference landmark {ref!r}: {res.skipped_landmarks[ref]}")
                res.belief_fl = dict(self._belief)
                res.estimates = self.estimates
                return res
        l1, l2 = self.reference
        others = {k: v for k, v in sets_fr.items() if k not in self.reference}
        fl = change_frame(sets_fr[l1], sets_fr[l2], others, self.n_l, self.rng, self.frame_change)
        frame = None if self.fusion == "product" else self._frame(regions)
        for name in self.landmarks:
            if name in self.reference:
                continue
            prev = self._weighted.get(name)
            p_t = fl.landmarks_fl.get(name)
            if prev is None or frame is None:
                if p_t is not None:
                    new = p_t if prev is None else fuse(prev[0], p_t, self.n_l, self.rng)
                    self._set_belief(name, new, np.ones(new.shape[0]))
                    res.fused.append(name)
                continue
            b1 = obs.bearings_o1_rad.get(name)
            b2 = obs.bearings_o2_rad.get(name)
            if b1 is None or b2 is None or not (math.isfinite(b1) and math.isfinite(b2)):
                continue
            q = self._fuse_likelihood(prev, frame, float(b1), float(b2), p_t)
            if q is None:
                res.skipped_landmarks[name] = "bearings have zero likelihood under the belief"
                continue
            self._set_belief(name, q.points_fl, q.weights)
            res.fused.append(name)
            if q.defensive:
                res.defensive.append(name)
        self._trajectory.append((fl.o1_fl, fl.o2_fl))
        self.used_movements.append(obs.index)
        res.particles_fl = fl.landmarks_fl
        res.o1_fl, res.o2_fl = fl.o1_fl, fl.o2_fl
        res.belief_fl = dict(self._belief)
        res.estimates = self.estimates
        return res

    def _set_belief(
        self, name: str, particles_fl: NDArray[np.float64], weights: NDArray[np.float64]
    ) -> None:
        self._weighted[name] = (particles_fl, weights)
        if particles_fl.shape[0] == self.n_l and np.all(weights == weights[0]):
            self._belief[name] = particles_fl
        else:
            self._belief[name] = particles_fl[systematic_resample(weights, self.n_l, self.rng)]

    def forget(self, name: str) -> None:
        """Drop the belief of landmark ``name`` (its name was found wrong); it starts afresh
        from its next bearings."""
        self._belief.pop(name, None)
        self._weighted.pop(name, None)

    @property
    def belief_fl(self) -> dict[str, NDArray[np.float64]]:
        """Current belief per non-reference landmark: (n_l, 2) FL."""
        return dict(self._belief)

    @property
    def estimates(self) -> dict[str, LandmarkEstimate]:
        """Current estimate per non-reference landmark seen so far."""
        return {
            k: LandmarkEstimate.from_particles(x, weights=w) for k, (x, w) in self._weighted.items()
        }

    @property
    def trajectory_fl(self) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
        """Per used movement, the particles (m, 2) of O1 and O2 in FL."""
        return list(self._trajectory)
