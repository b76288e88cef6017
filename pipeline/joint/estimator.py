"""The joint estimator: one factor graph over every keyframe and landmark, updated by iSAM2.

Per movement: the paper's filter (:class:`pipeline.slam.BearingSlam`) runs first as the
initializer. The map starts (bootstrap) with a batch solve of the first movements whose
reference pair can be triangulated, once their bearings over-determine them; later movements are
placed by resection against the landmarks already in the graph (L1, L2 included), and a movement
that cannot be placed yet waits and is tried again as the map grows. Every bearing of a placed
movement becomes a bearing factor (Huber loss) or waits until its landmark enters the graph
(rays from placed keyframes that meet with enough parallax, or a tight particle belief of the
initializer); iSAM2 updates the map; the bearing noise is estimated from the residuals; a
divergence check re-initializes the graph from the initializer's particles. Covariances are
iSAM2's marginals scaled by the estimated noise. Maths and departures from the paper:
docs/method.md.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import gtsam
import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad
from data_schemas.errors import EstimationError
from pipeline.crb import truncated_gaussian_std
from pipeline.estimate import LandmarkEstimate
from pipeline.frame_change import to_fl
from pipeline.fusion import PAPER_N_L, PAPER_N_R
from pipeline.geometry import (
    KeyframePose,
    MovementPose,
    Sightings,
    determinacy,
    intersect_rays,
    pose_params,
    predicted_bearings,
    resect,
    triangulate_fr,
    widest_std,
)
from pipeline.joint import graph as g
from pipeline.joint.noise import NoiseEstimate, estimate_noise, robust_std
from pipeline.joint.result import JointMovementResult
from pipeline.joint.table import BearingTable, by_landmark
from pipeline.priors import PriorName
from pipeline.slam import BearingSlam, MovementObservation, MovementStatus, Placement, skipped

#: Smallest angle between two rays of a landmark for it to enter the graph by intersection, in
#: units of eps (the paper's own bound for a usable cone intersection is 2 eps).
MIN_RAY_PARALLAX_EPS = 2.0
#: A movement is placed only if its resection's robust residual is at most this many eps ...
RESECTION_MAX_EPS = 2.0
#: ... and its start point (std at the prior noise, relative to its median distance to the
#: landmarks it sees) and its length (std of log d) are this well determined.
RESECTION_MAX_REL_STD = 0.25
RESECTION_MAX_LOG_STD = 0.5
#: A movement these bounds did not determine is resected again, though it sees the same mapped
#: landmarks, once its last fit is within this many times the bounds (the map moved under it).
UNDETERMINED_MARGIN = 2.0
#: The bootstrap waits for this many more bearings than unknowns (a check on its fit), unless
#: every movement in it has a reference pair the paper would use (parallax over 2 eps).
BOOTSTRAP_DOF = 2
#: A particle belief of the initializer this tight (sqrt of the largest covariance eigenvalue,
#: FL) puts its landmark in the graph at the belief's mean.
TIGHT_BELIEF_FL = 0.1
#: A landmark "jumps" when one update moves it by more than this (FL) ...
JUMP_FL = 0.1
#: ... and by more than this many standard deviations of its previous estimate.
JUMP_SIGMAS = 5.0
#: The model's noise is re-tuned (graph rebuilt) when the estimate leaves this ratio band ...
RETUNE_RATIO = 1.5
#: ... with at least this many degrees of freedom.
RETUNE_DOF = 10
#: A bearing this many eps from the map is taken out of the graph (the error bound is eps).
REJECT_EPS = 2.0
#: Up to this many movements the map is solved carefully: Powell's dogleg steps, relinearization
#: threshold 1e-3 and one more step after every update (a Gauss-Newton step from the bootstrap's
#: optimum along a barely determined direction can throw the map away); from then on, with the
#: map determined, plain Gauss-Newton steps relinearized per variable, whose cost per movement
#: does not grow with the dogleg's steps over the whole tree.
CAREFUL_MOVEMENTS = 50
#: A rejected bearing this close (eps) to the map is put back.
READMIT_EPS = 1.5
#: More than this fraction of the bearings beyond REJECT_EPS eps: the map is wrong, not them.
MAX_REJECT_FRACTION = 0.1
#: A landmark with at least this many rejected bearings, and more rejected than kept, is put
#: where its rays meet (its first estimate was wrong, not its bearings).
RESEAT_MIN_REJECTED = 3


@dataclass
class _Movement:
    """A movement's bearings (catalog landmarks, finite), commanded turn and driven distance."""

    index: int
    turn_rad: float | None
    bearings: list[g.Bearing]
    distance_m: float | None = None

    def observation(self) -> MovementObservation:
        """The bearings back as a :class:`MovementObservation`."""
        ends: tuple[dict[str, float], dict[str, float]] = ({}, {})
        for b in self.bearings:
            ends[b.end][b.landmark] = b.bearing_rad
        return MovementObservation(self.index, ends[0], ends[1], self.turn_rad, self.distance_m)


def _reach(s: Sightings, o1_fl: NDArray[np.float64]) -> float:
    """Median distance (FL) of the sighted landmarks from O1 (2,)."""
    return float(np.median(np.hypot(*(s.points_fl - o1_fl).T)))


#: What a movement saw of the map: whether its start is pinned (previous movement placed), how
#: many bearings it has, and the mapped landmarks of its bearings (in order).
_Seen = tuple[bool, int, tuple[str, ...]]


@dataclass
class _MapState:
    """What a rollback restores: the movements (placed in the graph, or waiting), the links
    between consecutive placed movements, the landmarks in the graph and the bearings waiting
    for theirs, the rejected bearings, the landmark estimates and the bearing noise.

    The rest of :class:`JointSlam` is derived from it and rebuilt after a rollback: the iSAM2
    graph (from the variables' values), the bearing table, the factor indices.
    """

    placed: dict[int, _Movement]
    waiting: dict[int, _Movement]
    links: set[tuple[int, int]]
    in_graph: set[str]
    pending: dict[str, list[g.Bearing]]
    rejected: set[g.Bearing]
    estimates: dict[str, LandmarkEstimate]
    noise: NoiseEstimate | None
    sigma_model_rad: float

    def copy(self) -> _MapState:
        """A copy whose containers are new (the movements themselves are shared)."""
        return _MapState(
            dict(self.placed),
            dict(self.waiting),
            set(self.links),
            set(self.in_graph),
            {k: list(v) for k, v in self.pending.items()},
            set(self.rejected),
            dict(self.estimates),
            self.noise,
            self.sigma_model_rad,
        )


class JointSlam:
    """Joint bearing-only SLAM over all movements (GTSAM iSAM2), initialized by the paper's filter.

    Parameters
    ----------
    landmarks, reference, vision_error_rad, rng, prior, n_r, n_l
        As :class:`pipeline.slam.BearingSlam` (the initializer).
    robust : bool
        Huber loss on the bearing factors (default on).
    turn_prior_sigma_rad : float or None
        Std of a prior on each turn in place from the commanded turn
        (``MovementObservation.turn_rad``); None (default) leaves the turn free.
    distance_prior_rel : float or None
        Relative std of a prior on each movement's length from its driven distance
        (``MovementObservation.distance_m``), through one scale variable (the map's FL units per
        metre, unknown); None leaves the lengths free.
    divergence_rms_rad : float or None
        The map counts as diverged when the robust RMS of its residuals exceeds this (default
        eps), or when a landmark jumps (:data:`JUMP_FL` and :data:`JUMP_SIGMAS`).
    """

    def __init__(
        self,
        landmarks: Sequence[str],
        reference: tuple[str, str],
        *,
        vision_error_rad: float,
        rng: np.random.Generator,
        prior: PriorName = "impartial",
        n_r: int = PAPER_N_R,
        n_l: int = PAPER_N_L,
        robust: bool = True,
        turn_prior_sigma_rad: float | None = None,
        distance_prior_rel: float | None = None,
        divergence_rms_rad: float | None = None,
    ) -> None:
        self.paper = BearingSlam(
            landmarks,
            reference,
            vision_error_rad=vision_error_rad,
            prior=prior,
            n_r=n_r,
            n_l=n_l,
            rng=rng,
        )
        if turn_prior_sigma_rad is not None and not turn_prior_sigma_rad > 0.0:
            raise EstimationError(f"turn prior std must be > 0, got {turn_prior_sigma_rad}")
        if distance_prior_rel is not None and not distance_prior_rel > 0.0:
            raise EstimationError(f"distance prior std must be > 0, got {distance_prior_rel}")
        self.landmarks = list(self.paper.landmarks)
        self.reference = reference
        self.eps_rad = float(vision_error_rad)
        self.robust = robust
        self.turn_prior_sigma_rad = turn_prior_sigma_rad
        self.distance_prior_rel = distance_prior_rel
        self.divergence_rms_rad = self.eps_rad if divergence_rms_rad is None else divergence_rms_rad
        self.sigma0_rad = truncated_gaussian_std(self.eps_rad)
        self._lm_index = {n: i for i, n in enumerate(self.landmarks)}
        self._state = _MapState(
            placed={},
            waiting={},
            links=set(),
            in_graph=set(reference),
            pending={},
            rejected=set(),
            estimates={},
            noise=None,
            sigma_model_rad=self.sigma0_rad,
        )
        # iSAM2 factor index of each bearing in the graph; bearings taken out as outliers
        self._factor_of: dict[g.Bearing, int] = {}
        self._staged: list[tuple[int, g.Bearing]] = []
        # movements the bearings did not determine: what they saw, where the fit put them
        self._undetermined: dict[int, tuple[_Seen, NDArray[np.float64], NDArray[np.bool_]]] = {}
        # the map's bearings as arrays, and their residuals at the map as it is (_residuals)
        self._table = BearingTable()
        self._residual_memo: tuple[gtsam.Values, int, NDArray[np.float64]] | None = None
        self.reinitializations = 0
        self._careful = True
        self._isam = self._new_isam()
        # iSAM2's estimate of every variable, computed when first asked after an update
        self._estimate: gtsam.Values | None = gtsam.Values()

    # ------------------------------------------------------------------ state
    @property
    def noise(self) -> NoiseEstimate | None:
        """The bearing noise estimated from the map's residuals (None before a map)."""
        return self._state.noise

    @property
    def sigma_model_rad(self) -> float:
        """The bearing std (rad) the bearing factors are weighted with now."""
        return self._state.sigma_model_rad

    def _new_isam(self) -> gtsam.ISAM2:
        """A fresh iSAM2, careful while the map has fewer than :data:`CAREFUL_MOVEMENTS`."""
        self._careful = len(self._state.placed) < CAREFUL_MOVEMENTS
        params = gtsam.ISAM2Params()
        params.relinearizeSkip = 1
        params.setFactorization("QR")
        if self._careful:
            params.setRelinearizeThreshold(1e-3)
            params.setOptimizationParams(gtsam.ISAM2DoglegParams())
        else:
            params.setRelinearizeThreshold(g.relinearize_thresholds())
            params.enablePartialRelinearizationCheck = True
            params.setOptimizationParams(gtsam.ISAM2GaussNewtonParams())
        return gtsam.ISAM2(params)

    @property
    def _values(self) -> gtsam.Values:
        """Every variable as iSAM2 estimates it now (one back-substitution after an update,
        then kept until the next; never changed in place)."""
        if self._estimate is None:
            self._estimate = self._isam.calculateEstimate()
        return self._estimate

    @_values.setter
    def _values(self, values: gtsam.Values) -> None:
        self._estimate = values

    def _retable(self) -> None:
        """The bearing table built anew from the placed movements (after a change of the map
        other than bearings added or rejected)."""
        self._table = BearingTable()
        self._table.add(self._bearings(), self._lm_index, self._state.rejected)

    def _key(self, name: str) -> int:
        return g.landmark_key(self._lm_index[name])

    def _point(self, name: str) -> NDArray[np.float64]:
        if self._estimate is None:  # one variable, not the whole map
            return np.asarray(self._isam.calculateEstimatePoint2(self._key(name)), np.float64)
        return np.asarray(self._values.atPoint2(self._key(name)), np.float64)

    def _has(self, key: int) -> bool:
        if self._estimate is None:
            return bool(self._isam.valueExists(key))
        return bool(self._estimate.exists(key))

    def _pose2(self, key: int) -> gtsam.Pose2:
        if self._estimate is None:
            return self._isam.calculateEstimatePose2(key)
        return self._values.atPose2(key)

    def _movement_pose(self, movement: int, values: gtsam.Values | None = None) -> MovementPose:
        k1, k2 = g.pose_key(movement, 0), g.pose_key(movement, 1)
        if values is None:
            p1, p2 = self._pose2(k1), self._pose2(k2)
        else:
            p1, p2 = values.atPose2(k1), values.atPose2(k2)
        o1 = np.array([p1.x(), p1.y()])
        o2 = np.array([p2.x(), p2.y()])
        return MovementPose(o1, p1.theta(), max(float(np.hypot(*(o2 - o1))), 1e-9))

    @property
    def estimates(self) -> dict[str, LandmarkEstimate]:
        """Current estimate per non-reference landmark in the graph (FL)."""
        return dict(self._state.estimates)

    @property
    def unit_m(self) -> float | None:
        """The map's unit |L1 L2| in metres, estimated through the distance prior (None without
        it, or before a movement with a distance is in the map)."""
        if not self._has(g.SCALE_KEY):
            return None
        if self._estimate is None:
            return math.exp(-float(self._isam.calculateEstimateVector(g.SCALE_KEY)[0]))
        return math.exp(-float(self._estimate.atVector(g.SCALE_KEY)[0]))

    @property
    def bearing_scatter(self) -> dict[str, tuple[int, float]]:
        """Per non-reference landmark in the map: how many bearings it has there and how widely
        they scatter about it, as the robust scale of their residuals (1.4826 times their median
        absolute value) over the map's bearing noise (:attr:`noise`). Near 1 for a landmark whose
        rays meet at one point; well above for bearings of several landmarks given one name."""
        if self._state.noise is None:
            return {}
        sigma = max(self._state.noise.sigma_rad, 1e-12)
        skip = [self._lm_index[n] for n in self.reference]
        return {
            self.landmarks[j]: (v.size, robust_std(v) / sigma)
            for j, v in by_landmark(self._table, self._residuals(), skip).items()
        }

    @property
    def used_movements(self) -> list[int]:
        """Indices of the movements in the graph, in order."""
        return sorted(self._state.placed)

    @property
    def waiting_movements(self) -> list[int]:
        """Indices of the movements not placed (yet)."""
        return sorted(self._state.waiting)

    @property
    def trajectory_fl(self) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
        """Per movement in the graph (index order), O1 and O2 as (1, 2) arrays in FL."""
        out = []
        for k in sorted(self._state.placed):
            mp = self._movement_pose(k)
            out.append((mp.o1_fl[None, :], mp.o2_fl[None, :]))
        return out

    def keyframe_poses(self) -> dict[tuple[int, int], KeyframePose]:
        """Every keyframe in the graph, ``(movement, end)`` (end 0: O1, 1: O2), as iSAM2 has it
        now: position and heading (FL) and the covariance of its tangent ``(x, y, heading)``
        in the keyframe's own frame (FL, rad), scaled by the estimated noise as the landmarks'
        covariances are. A keyframe whose marginal iSAM2 cannot give (an indeterminate
        system) is left out."""
        scale = 1.0
        if self._state.noise is not None:
            scale = self._state.noise.variance_rad2 / self._state.sigma_model_rad**2
        out = {}
        for k in sorted(self._state.placed):
            for end in (0, 1):
                key = g.pose_key(k, end)
                p = self._values.atPose2(key)
                try:
                    cov = np.asarray(self._isam.marginalCovariance(key), np.float64) * scale
                except RuntimeError:  # GTSAM's indeterminate linear system
                    continue
                out[k, end] = KeyframePose(
                    np.array([p.x(), p.y()]), float(p.theta()), 0.5 * (cov + cov.T)
                )
        return out

    # ------------------------------------------------------------------ placement
    def _sightings(self, m: _Movement) -> Sightings:
        used = [b for b in m.bearings if b.landmark in self._state.in_graph]
        return Sightings(
            np.array([self._point(b.landmark) for b in used], np.float64).reshape(-1, 2),
            np.array([b.end for b in used], np.int64),
            np.array([b.bearing_rad for b in used], np.float64),
        )

    def _reference_guess(self, obs: MovementObservation) -> MovementPose | None:
        """The paper's frame: the movement seen through the reference pair's triangulation."""
        l1, l2 = self.reference
        b1, b2 = obs.bearings_o1_rad, obs.bearings_o2_rad
        if not all(r in b1 and r in b2 for r in self.reference):
            return None
        s1 = triangulate_fr(b1[l1], b2[l1])
        s2 = triangulate_fr(b1[l2], b2[l2])
        if s1 is None or s2 is None:
            return None
        o = to_fl(np.array([[0.0, 0.0], [1.0, 0.0]]), s1, s2)
        d = o[1] - o[0]
        return MovementPose(o[0], math.atan2(d[1], d[0]), float(np.hypot(*d)))

    def _paper_frame(self, obs: MovementObservation) -> bool:
        """Whether both reference landmarks have the parallax the paper asks (over 2 eps)."""
        b1, b2 = obs.bearings_o1_rad, obs.bearings_o2_rad
        return all(
            r in b1 and r in b2 and abs(wrap_rad(b2[r] - b1[r])) > 2.0 * self.eps_rad
            for r in self.reference
        )

    def _place(self, m: _Movement) -> tuple[MovementPose, set[g.Bearing]] | str:
        """The movement's pose by resection against the map and its bearings beyond
        :data:`REJECT_EPS` eps of it (wrong detections), or why it cannot be placed.

        A movement the bearings did not determine is not resected again while it sees the same
        mapped landmarks with the same bearings and the same start (placed previous movement
        or not), as long as they still clearly (:data:`UNDETERMINED_MARGIN`) do not determine
        it at the pose last fitted against the map as it is now. A fit that determines nothing
        at all (singular) is no such evidence: a degenerate local optimum looks the same.
        """
        used = [b for b in m.bearings if b.landmark in self._state.in_graph]
        s = self._sightings(m)
        n1 = int((s.end == 0).sum())
        n2 = int((s.end == 1).sum())
        chained = m.index - 1 in self._state.placed
        need = 2 if chained else 4
        if n1 < 1 or n2 < 1 or n1 + n2 < need:
            return (
                f"too few bearings of mapped landmarks ({n1} at O1, {n2} at O2; "
                f"need one at each and {need} in all)"
            )
        seen = (chained, len(m.bearings), tuple(b.landmark for b in used))
        held = self._undetermined.get(m.index)
        if held is not None and held[0] == seen:
            x, keep = held[1], held[2]
            why = self._undetermined_why(
                *determinacy(s.subset(keep), x, o1_known=chained),
                _reach(s, x[:2]),
                margin=UNDETERMINED_MARGIN,
            )
            if why is not None:
                return why
        guess = self._reference_guess(m.observation())
        o1_known = self._movement_pose(m.index - 1).o2_fl if chained else None
        found = resect(
            s,
            guesses=[] if guess is None else [guess],
            o1_known_fl=o1_known,
            outlier_rad=RESECTION_MAX_EPS * self.eps_rad,
        )
        if found is None:
            return "no bearing of a mapped landmark at O1"
        robust = robust_std(found.residuals_rad)
        if robust > RESECTION_MAX_EPS * self.eps_rad:
            return (
                f"resection does not fit the map (robust residual {math.degrees(robust):.2f} "
                f"deg > {RESECTION_MAX_EPS:g} eps)"
            )
        why = self._undetermined_why(
            found.position_std_fl, found.log_length_std, _reach(s, found.pose.o1_fl)
        )
        if why is not None:
            if math.isfinite(found.position_std_fl) and math.isfinite(found.log_length_std):
                self._undetermined[m.index] = (seen, pose_params(found.pose), found.inliers)
            return why
        self._undetermined.pop(m.index, None)
        far = np.abs(found.residuals_rad) > REJECT_EPS * self.eps_rad
        return found.pose, {b for b, out in zip(used, far, strict=True) if out}

    def _undetermined_why(
        self, position_std: float, log_length_std: float, reach_fl: float, *, margin: float = 1.0
    ) -> str | None:
        """Why bearings do not determine a movement, from the stds of its fit for a bearing
        noise of 1 rad (:func:`pipeline.geometry.determinacy`) and the median distance
        (FL) of the landmarks from O1 (None when they do, within ``margin`` times the bounds)."""
        rel = position_std * self.sigma0_rad / max(reach_fl, 1e-9)
        logd = log_length_std * self.sigma0_rad
        if rel > margin * RESECTION_MAX_REL_STD or logd > margin * RESECTION_MAX_LOG_STD:
            return (
                f"bearings of mapped landmarks do not determine the movement (relative std of "
                f"O1 {rel:.2g}, of log length {logd:.2g})"
            )
        return None

    def _links_of(self, k: int) -> list[tuple[int, int]]:
        """In-place links of movement ``k`` to its placed neighbours."""
        return [
            (a, b) for a, b in ((k - 1, k), (k, k + 1)) if {a, b} - {k} <= set(self._state.placed)
        ]

    def _distance_m(self, m: _Movement) -> float | None:
        """The distance the prior uses for ``m`` (None: no prior, or no usable distance)."""
        d = m.distance_m
        if self.distance_prior_rel is None or d is None or not (math.isfinite(d) and d > 0.0):
            return None
        return d

    def _distance_factor(self, movement: int, distance_m: float) -> gtsam.NonlinearFactor:
        return g.distance_factor(
            g.pose_key(movement, 0),
            g.pose_key(movement, 1),
            distance_m,
            self.distance_prior_rel or 0.0,
            self.robust,
        )

    def _link_factor(self, link: tuple[int, int]) -> gtsam.NonlinearFactor:
        a, b = link
        turn = self._state.placed[b].turn_rad if self.turn_prior_sigma_rad is not None else None
        return g.in_place_factor(
            g.pose_key(a, 1), g.pose_key(b, 0), turn, self.turn_prior_sigma_rad or 0.0
        )

    def _add(
        self,
        m: _Movement,
        pose: MovementPose,
        graph: gtsam.NonlinearFactorGraph,
        values: gtsam.Values,
        outliers: set[g.Bearing] | None = None,
    ) -> None:
        """Put a placed movement's poses, constraints and bearings into ``graph``/``values``
        (``outliers`` stay out, as rejected)."""
        links = self._links_of(m.index)
        self._state.placed[m.index] = m
        self._state.waiting.pop(m.index, None)
        graph.add(g.straight_factor(g.pose_key(m.index, 0), g.pose_key(m.index, 1)))
        for end, p2 in enumerate(_pose2s(pose)):
            key = g.pose_key(m.index, end)
            values.insert(key, p2)
            graph.add(g.weak_pose_prior(key, p2))
        distance = self._distance_m(m)
        if distance is not None:
            if not values.exists(g.SCALE_KEY) and not self._has(g.SCALE_KEY):
                log_scale = math.log(pose.length_fl / distance)
                values.insert(g.SCALE_KEY, np.array([log_scale]))
                graph.add(g.weak_scale_prior(log_scale))
            graph.add(self._distance_factor(m.index, distance))
        for link in links:
            self._state.links.add(link)
            graph.add(self._link_factor(link))
        noise = self._bearing_noise()
        for b in m.bearings:
            if outliers and b in outliers:
                self._state.rejected.add(b)
            elif b.landmark in self._state.in_graph:
                self._add_bearing(graph, b, noise)
            else:
                self._state.pending.setdefault(b.landmark, []).append(b)
        mapped = [b for b in m.bearings if b.landmark in self._state.in_graph]
        self._table.add(mapped, self._lm_index, outliers or ())

    def _enter_pending(self, graph: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> list[str]:
        """Landmarks that can enter the graph now, with their waiting bearings."""
        entered = []
        noise = self._bearing_noise()
        for name in sorted(self._state.pending, key=self._lm_index.__getitem__):
            point = self._initial_point(name, values)
            if point is None:
                continue
            values.insert(self._key(name), point)
            graph.add(g.weak_point_prior(self._key(name), point))
            waiting = self._state.pending.pop(name)
            for bearing in waiting:
                self._add_bearing(graph, bearing, noise)
            self._table.add(waiting, self._lm_index)
            self._state.in_graph.add(name)
            entered.append(name)
        return entered

    def _add_bearing(
        self, graph: gtsam.NonlinearFactorGraph, b: g.Bearing, noise: gtsam.noiseModel.Base
    ) -> None:
        """Add a bearing factor to ``graph``, remembering where (for its iSAM2 index)."""
        self._staged.append((graph.size(), b))
        graph.add(self._bearing_factor(b, noise))

    def _update(
        self,
        graph: gtsam.NonlinearFactorGraph,
        values: gtsam.Values,
        remove: Sequence[int] = (),
    ) -> None:
        """One iSAM2 update, factor indices recorded (one more relinearization step while the
        map is careful, :data:`CAREFUL_MOVEMENTS`); the estimate is computed when asked."""
        result = self._isam.update(graph, values, list(remove))
        index = result.getNewFactorsIndices()
        for pos, b in self._staged:
            self._factor_of[b] = int(index[pos])
        self._staged.clear()
        self._estimate = None
        if self._careful:
            self._isam.update()

    def _reject_outliers(self) -> None:
        """Take out bearings beyond :data:`REJECT_EPS` eps of the map; put back rejected ones
        within :data:`READMIT_EPS` eps.

        The method's bearing error is bounded by eps, so a residual that far is a wrong
        detection (the Huber loss only bounds its pull)."""
        r = np.abs(self._residuals())
        rejected = self._table.rejected
        out = self._table.select(~rejected & (r > REJECT_EPS * self.eps_rad))
        back = self._table.select(rejected & (r <= READMIT_EPS * self.eps_rad))
        if not out and not back:
            return
        graph = gtsam.NonlinearFactorGraph()
        noise = self._bearing_noise()
        for b in back:
            self._state.rejected.discard(b)
            self._add_bearing(graph, b, noise)
        remove = [self._factor_of.pop(b) for b in out]
        self._state.rejected.update(out)
        self._table.set_rejected(back, False)
        self._table.set_rejected(out, True)
        self._update(graph, gtsam.Values(), remove)

    def _reseat_landmarks(self) -> list[str]:
        """Landmarks moved to where their rays meet, when most of their bearings were rejected
        (the landmark is wrong, not its bearings: it entered from a poor first estimate); the
        map is then rebuilt with those bearings back in."""
        skip = [self._lm_index[n] for n in self.reference]
        n_rows = by_landmark(self._table, np.ones(len(self._table), np.int64), skip)
        n_rejected = by_landmark(self._table, self._table.rejected.astype(np.int64), skip)
        values: gtsam.Values | None = None
        moved = []
        for j, out_j in n_rejected.items():
            n_out = int(out_j.sum())
            if n_out < RESEAT_MIN_REJECTED or n_out <= n_rows[j].size - n_out:
                continue
            name = self.landmarks[j]
            own = self._table.select(self._table.landmark == j)
            poses = [self._values.atPose2(g.pose_key(b.movement, b.end)) for b in own]
            origins = np.array([(p.x(), p.y()) for p in poses], np.float64)
            headings = np.array([p.theta() for p in poses], np.float64)
            bearings = np.array([b.bearing_rad for b in own], np.float64)
            fix = intersect_rays(origins, headings + bearings, REJECT_EPS * self.eps_rad)
            if fix is None or fix.parallax_rad < MIN_RAY_PARALLAX_EPS * self.eps_rad:
                continue
            pts = np.repeat(fix.point_fl[None, :], len(own), axis=0)
            r = wrap_rad(bearings - predicted_bearings(origins, headings, pts))
            if int((np.abs(r) <= REJECT_EPS * self.eps_rad).sum()) <= len(own) - n_out:
                continue
            if values is None:
                values = gtsam.Values(self._values)
            values.update(self._key(name), fix.point_fl)
            self._state.rejected.difference_update(own)
            self._table.set_rejected(own, False)
            moved.append(name)
        if values is not None:
            self._rebuild(values)
        return moved

    def _place_waiting(self) -> list[int]:
        """Place every waiting movement the map can place now (again while any is placed)."""
        placed: list[int] = []
        progress = True
        while progress and self._state.waiting:
            progress = False
            for k in sorted(self._state.waiting):
                m = self._state.waiting[k]
                found = self._place(m)
                if isinstance(found, str):
                    continue
                graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
                self._add(m, found[0], graph, values, found[1])
                self._enter_pending(graph, values)
                self._update(graph, values)
                placed.append(k)
                progress = True
        return placed

    def _bootstrap(self) -> list[int] | str:
        """Start the map: one batch solve over the waiting movements with a reference frame."""
        guesses = {}
        for k in sorted(self._state.waiting):
            guess = self._reference_guess(self._state.waiting[k].observation())
            if guess is not None:
                guesses[k] = guess
        if not guesses:
            return "no movement sees the reference pair with parallax yet (the map starts there)"
        seeds: dict[str, list[NDArray[np.float64]]] = {}
        for k, guess in guesses.items():
            obs = self._state.waiting[k].observation()
            for name, b1 in obs.bearings_o1_rad.items():
                b2 = obs.bearings_o2_rad.get(name)
                if name in self.reference or b2 is None:
                    continue
                p = triangulate_fr(b1, b2)
                if p is not None:
                    c, sn = math.cos(guess.heading_rad), math.sin(guess.heading_rad)
                    p_fl = guess.o1_fl + guess.length_fl * np.array(
                        [c * p[0] - sn * p[1], sn * p[0] + c * p[1]]
                    )
                    seeds.setdefault(name, []).append(p_fl)
        n_bearings = sum(
            1
            for k in guesses
            for b in self._state.waiting[k].bearings
            if b.landmark in self.reference or b.landmark in seeds
        )
        n_links = sum(1 for k in guesses if k - 1 in guesses)
        dof = n_bearings - (4 * len(guesses) - 2 * n_links + 2 * len(seeds))
        paper_frames = all(self._paper_frame(self._state.waiting[k].observation()) for k in guesses)
        if dof < (0 if paper_frames else BOOTSTRAP_DOF):
            alone = (
                "; one movement alone never has more: the map waits for another that sees "
                "both reference landmarks from both ends"
                if len(guesses) == 1
                else ""
            )
            return (
                f"waiting for more bearings to start the map ({dof} more bearings than unknowns, "
                f"need {BOOTSTRAP_DOF}{alone})"
            )
        before = self._state.copy()
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        l1, l2 = self.reference
        for f in g.gauge_factors(self._key(l1), self._key(l2)):
            graph.add(f)
        values.insert(self._key(l1), np.array([0.0, 0.0]))
        values.insert(self._key(l2), np.array([1.0, 0.0]))
        for name, pts in seeds.items():
            point = np.median(np.array(pts), axis=0)
            values.insert(self._key(name), point)
            graph.add(g.weak_point_prior(self._key(name), point))
            self._state.in_graph.add(name)
        for k, guess in guesses.items():
            self._add(self._state.waiting[k], guess, graph, values)
        try:
            solved = g.solve_batch(graph, values)
        except RuntimeError as exc:
            solved = None
            why = f"bootstrap failed ({str(exc).strip().splitlines()[0]})"
        if solved is not None:
            self._values = solved
            r = self._residuals()
            robust = robust_std(r) if r.size else 0.0
            why = (
                f"bootstrap does not fit (robust residual {math.degrees(robust):.2f} deg > eps)"
                if robust > self.eps_rad
                else ""
            )
        if why or solved is None:  # undo: the movements wait again
            self._state = before
            self._staged.clear()
            self._table = BearingTable()
            self._values = gtsam.Values()
            return why or "bootstrap failed"
        self._isam = self._new_isam()
        self._update(graph, solved)
        return sorted(guesses)

    # ------------------------------------------------------------------ landmarks
    def _initial_point(self, name: str, values: gtsam.Values) -> NDArray[np.float64] | None:
        """Initial value for a landmark not in the graph, from its rays or the particles."""
        origins, dirs = [], []
        for b in self._state.pending.get(name, []):
            key = g.pose_key(b.movement, b.end)
            pose = values.atPose2(key) if values.exists(key) else self._pose2(key)
            origins.append((pose.x(), pose.y()))
            dirs.append(pose.theta() + b.bearing_rad)
        fix = intersect_rays(
            np.array(origins, np.float64).reshape(-1, 2), np.array(dirs), 2.0 * self.eps_rad
        )
        if (
            fix is not None
            and fix.parallax_rad >= MIN_RAY_PARALLAX_EPS * self.eps_rad
            and fix.rms_rad <= self.eps_rad
        ):
            return fix.point_fl
        belief = self.paper.estimates.get(name)
        if belief is not None and widest_std(belief.cov_fl) <= TIGHT_BELIEF_FL:
            return np.asarray(belief.mean_fl, np.float64)
        return None

    # ------------------------------------------------------------------ graph
    def _bearing_noise(self) -> gtsam.noiseModel.Base:
        return g.bearing_noise(self._state.sigma_model_rad, self.robust)

    def _bearing_factor(self, b: g.Bearing, noise: gtsam.noiseModel.Base) -> gtsam.NonlinearFactor:
        return g.bearing_factor(
            g.pose_key(b.movement, b.end), self._key(b.landmark), b.bearing_rad, noise
        )

    def _bearings(self, rejected: bool = True) -> list[g.Bearing]:
        """Every bearing of the placed movements whose landmark is in the graph (with or
        without the rejected ones)."""
        return [
            b
            for k in sorted(self._state.placed)
            for b in self._state.placed[k].bearings
            if b.landmark in self._state.in_graph and (rejected or b not in self._state.rejected)
        ]

    def _full_graph(self, values: gtsam.Values) -> gtsam.NonlinearFactorGraph:
        """Every factor of the map (for a rebuild), weak priors at ``values``."""
        graph = gtsam.NonlinearFactorGraph()
        l1, l2 = self.reference
        for f in g.gauge_factors(self._key(l1), self._key(l2)):
            graph.add(f)
        for name in self._state.in_graph - set(self.reference):
            key = self._key(name)
            graph.add(g.weak_point_prior(key, np.asarray(values.atPoint2(key), np.float64)))
        if values.exists(g.SCALE_KEY):
            graph.add(g.weak_scale_prior(float(values.atVector(g.SCALE_KEY)[0])))
        for k in sorted(self._state.placed):
            graph.add(g.straight_factor(g.pose_key(k, 0), g.pose_key(k, 1)))
            for end in (0, 1):
                key = g.pose_key(k, end)
                graph.add(g.weak_pose_prior(key, values.atPose2(key)))
            distance = self._distance_m(self._state.placed[k])
            if distance is not None and values.exists(g.SCALE_KEY):
                graph.add(self._distance_factor(k, distance))
        for link in sorted(self._state.links):
            graph.add(self._link_factor(link))
        noise = self._bearing_noise()
        self._factor_of.clear()
        for b in self._bearings(rejected=False):
            self._add_bearing(graph, b, noise)
        return graph

    def _rebuild(self, values: gtsam.Values) -> None:
        """A fresh iSAM2 over every factor, from ``values`` refined by Levenberg-Marquardt."""
        graph = self._full_graph(values)
        # an indeterminate system keeps the initial values; iSAM2 below still solves from them
        with contextlib.suppress(RuntimeError):
            values = g.solve_batch(graph, values)
        self._isam = self._new_isam()
        self._update(graph, values)

    def _values_from_particles(self) -> gtsam.Values:
        """Initial values from the initializer's beliefs, keyframes re-placed against them."""
        values = gtsam.Values()
        for name in self._state.in_graph:
            belief = self.paper.estimates.get(name)
            point = belief.mean_fl if belief is not None else self._point(name)
            values.insert(self._key(name), np.asarray(point, np.float64))
        old, self._values = self._values, values
        for k in sorted(self._state.placed):
            m = self._state.placed[k]
            s = self._sightings(m)
            o1_known = (
                self._movement_pose(k - 1, values).o2_fl if k - 1 in self._state.placed else None
            )
            found = (
                resect(
                    s,
                    guesses=[],
                    o1_known_fl=o1_known,
                    outlier_rad=RESECTION_MAX_EPS * self.eps_rad,
                )
                if s.bearings_rad.size
                else None
            )
            pose = found.pose if found is not None else self._movement_pose(k, old)
            for end, p in enumerate(_pose2s(pose)):
                values.insert(g.pose_key(k, end), p)
        if old.exists(g.SCALE_KEY):
            values.insert(g.SCALE_KEY, old.atVector(g.SCALE_KEY))
        return values

    # ------------------------------------------------------------------ checks
    def _residuals(self) -> NDArray[np.float64]:
        """The residual (rad) of every bearing of the map (a row of the bearing table) under
        the current values; kept until the values are replaced or the table changes."""
        memo = self._residual_memo
        if memo is not None and memo[0] is self._values and memo[1] == self._table.version:
            return memo[2]
        r = self._table.residuals(self._values)
        r.setflags(write=False)  # shared by the callers until the map changes
        self._residual_memo = (self._values, self._table.version, r)  # holds the values
        return r

    def _n_params(self) -> int:
        """Free parameters of the keyframes and landmarks. The bearings still determine them
        with a distance prior, whose std is loose against the lengths the bearings give: not
        counting its share keeps the noise estimate on the safe side."""
        return (
            2 * (len(self._state.in_graph) - 2)
            + 4 * len(self._state.placed)
            - 2 * len(self._state.links)
        )

    def _jumped(self, before: dict[str, LandmarkEstimate]) -> str:
        for name, prev in before.items():
            if name not in self._state.in_graph:
                continue
            step = float(np.hypot(*(self._point(name) - prev.mean_fl)))
            spread = widest_std(prev.cov_fl)
            if step > JUMP_FL and step > JUMP_SIGMAS * spread:
                return f"{name} jumped {step:.3f} FL ({step / max(spread, 1e-12):.0f} sigma)"
        return ""

    def _check(self, before: dict[str, LandmarkEstimate]) -> str:
        """Why the map looks diverged (empty if it does not)."""
        return self._misfit(self.divergence_rms_rad) or self._jumped(before)

    def _misfit(self, rms_limit_rad: float) -> str:
        """Why the residuals are out of bounds: too many beyond :data:`REJECT_EPS` eps, or a
        robust RMS over ``rms_limit_rad`` (empty if they are not)."""
        r = self._residuals()
        far = int((~self._table.rejected & (np.abs(r) > REJECT_EPS * self.eps_rad)).sum())
        if far > max(1, MAX_REJECT_FRACTION * r.size):
            return f"{far} of {r.size} bearings more than {REJECT_EPS:g} eps from the map"
        noise = estimate_noise(r, self._n_params(), self.sigma0_rad)
        if noise.robust_rms_rad > rms_limit_rad:
            limit = math.degrees(rms_limit_rad)
            return f"robust residual RMS {math.degrees(noise.robust_rms_rad):.2f} deg > {limit:.2f}"
        return ""

    def _update_estimates(self) -> None:
        r = self._residuals()
        self._state.noise = estimate_noise(r, self._n_params(), self.sigma0_rad, self.eps_rad)
        n = self._state.noise
        off = abs(math.log(n.sigma_rad / self._state.sigma_model_rad))
        if n.dof >= RETUNE_DOF and off > math.log(RETUNE_RATIO):
            self._state.sigma_model_rad = n.sigma_rad
            self._rebuild(self._values)
            r = self._residuals()
            self._state.noise = estimate_noise(r, self._n_params(), self.sigma0_rad, self.eps_rad)
        scale = self._state.noise.variance_rad2 / self._state.sigma_model_rad**2
        out = {}
        for name in sorted(
            self._state.in_graph - set(self.reference), key=self._lm_index.__getitem__
        ):
            cov = np.asarray(self._isam.marginalCovariance(self._key(name)), np.float64) * scale
            out[name] = LandmarkEstimate(self._point(name), 0.5 * (cov + cov.T))
        self._state.estimates = out

    def forget(self, name: str) -> None:
        """Take landmark ``name`` out of the map with every bearing given to it so far (an
        association step found its name wrong); :meth:`add_history` may give it again."""
        if name in self.reference or name not in self._lm_index:
            return
        for m in (*self._state.placed.values(), *self._state.waiting.values()):
            m.bearings[:] = [b for b in m.bearings if b.landmark != name]
        self._state.pending.pop(name, None)
        self._state.rejected = {b for b in self._state.rejected if b.landmark != name}
        self.paper.forget(name)
        self._state.estimates.pop(name, None)
        if name in self._state.in_graph:
            self._state.in_graph.discard(name)
            self._retable()
            values = gtsam.Values(self._values)
            values.erase(self._key(name))
            self._rebuild(values)
            self._update_estimates()

    def add_history(self, name: str, bearings: Sequence[tuple[int, int, float]]) -> None:
        """Bearings of ``name`` from movements already in the graph, known only now.

        An association step names a landmark of a shared class once it is confirmed; its
        earlier bearings ``(movement, end, bearing_rad)`` join their movement (placed or waiting)
        and wait with the landmark's own until it enters the graph (other movements: ignored).
        """
        if name not in self._lm_index or name in self._state.in_graph:
            return
        for movement, end, b in bearings:
            m = self._state.placed.get(movement) or self._state.waiting.get(movement)
            if m is None or not math.isfinite(b):
                continue
            bearing = g.Bearing(movement, end, name, float(b))
            m.bearings.append(bearing)
            if movement in self._state.placed:  # a waiting movement brings it when placed
                self._state.pending.setdefault(name, []).append(bearing)

    def settle(self) -> list[str]:
        """Enter the landmarks whose bearings wait (given by :meth:`add_history` after the
        last movement) and update the map, without a movement; their names."""
        if not self._state.placed or not self._state.pending:
            return []
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        entered = self._enter_pending(graph, values)
        if entered:
            self._update(graph, values)
            self._reject_outliers()
            self._update_estimates()
        return entered

    # ------------------------------------------------------------------ one movement
    def process_movement(self, obs: MovementObservation) -> JointMovementResult:
        """Initialize with the paper's filter, place the movement, add its bearings, update."""
        res = self._process_movement(obs)
        res.unit_m = self.unit_m
        return res

    @staticmethod
    def _initializing(obs: MovementObservation, mapped: set[str]) -> MovementObservation:
        """The movement as the initializer (the paper's filter) sees it: without the ``mapped``
        landmarks (in the graph beside the reference pair), whose bearings refine them there."""

        def keep(bearings_rad: Mapping[str, float]) -> dict[str, float]:
            return {k: b for k, b in bearings_rad.items() if k not in mapped}

        return replace(
            obs,
            bearings_o1_rad=keep(obs.bearings_o1_rad),
            bearings_o2_rad=keep(obs.bearings_o2_rad),
        )

    def _process_movement(self, obs: MovementObservation) -> JointMovementResult:
        mapped = self._state.in_graph - set(self.reference)
        p = self.paper.process_movement(self._initializing(obs, mapped))
        res = JointMovementResult(
            obs.index,
            MovementStatus.OK,
            fused=list(p.fused),
            defensive=list(p.defensive),
            cones_fr=p.cones_fr,
            particles_fr=p.particles_fr,
            particles_fl=p.particles_fl,
            belief_fl={k: v for k, v in p.belief_fl.items() if k not in mapped},
        )
        # the paper's per-landmark skips concern its two-view cones; the joint map uses every
        # single bearing, so only names outside the catalog are reported
        res.skipped_landmarks = {
            n: r for n, r in p.skipped_landmarks.items() if n not in self._lm_index
        }
        bearings = [
            g.Bearing(obs.index, end, name, float(b))
            for end, bmap in enumerate((obs.bearings_o1_rad, obs.bearings_o2_rad))
            for name, b in bmap.items()
            if name in self._lm_index and math.isfinite(b)
        ]
        if obs.index in self._state.placed or obs.index in self._state.waiting:
            raise EstimationError(f"movement {obs.index} was already processed")
        m = _Movement(obs.index, obs.turn_rad, bearings, obs.distance_m)
        if self._careful and len(self._state.placed) >= CAREFUL_MOVEMENTS:
            self._rebuild(self._values)  # the map is determined: plain steps from now on
        # the state and the values before the movement (values are never changed in place)
        snapshot, snapshot_values = self._state.copy(), self._values
        self._state.waiting[obs.index] = m
        before = self.estimates
        placed: list[int] = []
        why = ""
        if not self._state.placed:
            boot = self._bootstrap()
            if isinstance(boot, str):
                why = boot
            else:
                placed = boot
                graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
                self._enter_pending(graph, values)
                self._update(graph, values)
        if self._state.placed:
            placed += self._place_waiting()
        if obs.index not in self._state.placed:
            reason = why or self._place(m)
            res.status = skipped(reason if isinstance(reason, str) else "not placed")
        if not placed:
            res.estimates, res.noise = self.estimates, self._state.noise
            return res
        res.placement = (
            Placement.REFERENCE_PAIR if p.status == MovementStatus.OK else Placement.RESECTION
        )
        res.also_placed = [k for k in placed if k != obs.index]
        divergence = self._check(before)
        if divergence:
            res.divergence = divergence
            self.reinitializations += 1
            self._rebuild(self._values_from_particles())
            still = self._misfit(max(self.eps_rad, self.divergence_rms_rad))
            if still:
                return self._roll_back(res, snapshot, snapshot_values, m, divergence, still)
        self._reject_outliers()
        if self._reseat_landmarks():
            self._reject_outliers()
        self._update_estimates()
        res.estimates, res.noise = self.estimates, self._state.noise
        if obs.index in self._state.placed:
            mp = self._movement_pose(obs.index)
            res.o1_fl, res.o2_fl = mp.o1_fl[None, :], mp.o2_fl[None, :]
            res.residuals_rad = self._movement_residuals(m)
        else:
            res.placement = Placement.NONE
        return res

    def _roll_back(
        self,
        res: JointMovementResult,
        snap: _MapState,
        snap_values: gtsam.Values,
        m: _Movement,
        divergence: str,
        still: str,
    ) -> JointMovementResult:
        """The map as it was before movement ``m``, which is refused when there was a map;
        without one, every movement waits for the bootstrap to try again with more."""
        self._state = snap
        self._staged.clear()
        self._factor_of.clear()
        self._retable()
        if self._state.placed:
            self._rebuild(snap_values)
        else:
            self._state.waiting[m.index] = m
            self._isam, self._values = self._new_isam(), gtsam.Values()
        res.status = skipped(
            f"the map diverged with it ({divergence}) and re-initialization from the "
            f"particles did not fit ({still}); the map is kept as before it"
        )
        res.placement, res.also_placed = Placement.NONE, []
        res.estimates, res.noise = self.estimates, self._state.noise
        return res

    def _movement_residuals(self, m: _Movement) -> dict[str, tuple[float | None, float | None]]:
        """Bearing residuals (rad) of one placed movement, per landmark in the graph."""
        out: dict[str, list[float | None]] = {}
        mp = self._movement_pose(m.index)
        for b in m.bearings:
            if b.landmark not in self._state.in_graph:
                continue
            o = mp.o1_fl if b.end == 0 else mp.o2_fl
            pt = self._point(b.landmark)
            pred = math.atan2(pt[1] - o[1], pt[0] - o[0]) - mp.heading_rad
            out.setdefault(b.landmark, [None, None])[b.end] = float(wrap_rad(b.bearing_rad - pred))
        return {
            n: (v[0], v[1]) for n, v in sorted(out.items(), key=lambda kv: self._lm_index[kv[0]])
        }


def _pose2s(pose: MovementPose) -> tuple[gtsam.Pose2, gtsam.Pose2]:
    o2 = pose.o2_fl
    return (
        gtsam.Pose2(float(pose.o1_fl[0]), float(pose.o1_fl[1]), pose.heading_rad),
        gtsam.Pose2(float(o2[0]), float(o2[1]), pose.heading_rad),
    )
