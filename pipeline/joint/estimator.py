"""The joint estimator: one factor graph over every keyframe and landmark, updated by iSAM2.

Per movement: the paper's filter (:class:`pipeline.slam.BearingSlam`) runs first as the
initializer; the movement is placed by resection against the landmarks already in the graph
(L1, L2 included); every bearing of the movement becomes a bearing factor (Huber loss) or waits
until its landmark enters the graph (rays from two or more placed keyframes that meet, or a
tight particle belief of the initializer); iSAM2 updates the map; the bearing noise is estimated
from the residuals; a divergence check re-initializes the graph from the initializer's particles.
Covariances are iSAM2's marginals scaled by the estimated noise. Maths: docs/method.md.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Sequence
from dataclasses import dataclass

import gtsam
import numpy as np
from numpy.typing import NDArray

from data_schemas.errors import EstimationError
from pipeline.batch_ls import triangulate_fr
from pipeline.crb import truncated_gaussian_std
from pipeline.estimate import LandmarkEstimate
from pipeline.frame_change import to_fl
from pipeline.joint import graph as g
from pipeline.joint.geometry import MovementPose, Sightings, intersect_rays, resect
from pipeline.joint.noise import NoiseEstimate, estimate_noise
from pipeline.joint.result import JointMovementResult
from pipeline.priors import PriorName
from pipeline.slam import BearingSlam, MovementObservation

#: Smallest angle between two rays of a landmark for it to enter the graph by intersection, in
#: units of eps (the paper's own bound for a usable cone intersection is 2 eps).
MIN_RAY_PARALLAX_EPS = 2.0
#: A movement is placed only if its resection's robust residual is at most this many eps.
RESECTION_MAX_EPS = 2.0
#: ... and its start point (std, FL, at the prior noise) and length (std of log d) are this well
#: determined by the bearings of mapped landmarks.
RESECTION_MAX_STD_FL = 0.5
RESECTION_MAX_LOG_STD = 0.5
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


@dataclass
class _Movement:
    index: int
    chained: bool
    turn_rad: float | None


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
    """

    def __init__(
        self,
        landmarks: Sequence[str],
        reference: tuple[str, str],
        *,
        vision_error_rad: float,
        rng: np.random.Generator,
        prior: PriorName = "impartial",
        n_r: int = 50,
        n_l: int = 300,
        robust: bool = True,
        turn_prior_sigma_rad: float | None = None,
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
        self.landmarks = list(self.paper.landmarks)
        self.reference = reference
        self.eps_rad = float(vision_error_rad)
        self.robust = robust
        self.turn_prior_sigma_rad = turn_prior_sigma_rad
        self.sigma0_rad = truncated_gaussian_std(self.eps_rad)
        self.sigma_model_rad = self.sigma0_rad
        self._lm_index = {n: i for i, n in enumerate(self.landmarks)}
        self._moves: list[_Movement] = []
        self._bearings: list[g.Bearing] = []
        self._in_graph: set[str] = set(reference)
        self._pending: dict[str, list[g.Bearing]] = {}
        self._estimates: dict[str, LandmarkEstimate] = {}
        self.noise: NoiseEstimate | None = None
        self.reinitializations = 0
        self._isam = self._new_isam()
        self._values = gtsam.Values()
        gauge = gtsam.NonlinearFactorGraph()
        l1, l2 = (self._lm_index[r] for r in reference)
        for f in g.gauge_factors(g.landmark_key(l1), g.landmark_key(l2)):
            gauge.add(f)
        init = gtsam.Values()
        init.insert(g.landmark_key(l1), np.array([0.0, 0.0]))
        init.insert(g.landmark_key(l2), np.array([1.0, 0.0]))
        self._isam.update(gauge, init)
        self._values = self._isam.calculateEstimate()

    # ------------------------------------------------------------------ state
    @staticmethod
    def _new_isam() -> gtsam.ISAM2:
        params = gtsam.ISAM2Params()
        params.setRelinearizeThreshold(1e-3)
        params.relinearizeSkip = 1
        params.setFactorization("QR")
        return gtsam.ISAM2(params)

    def _point(self, name: str) -> NDArray[np.float64]:
        return np.asarray(self._values.atPoint2(g.landmark_key(self._lm_index[name])), np.float64)

    def _pose(self, movement: int, end: int) -> gtsam.Pose2:
        return self._values.atPose2(g.pose_key(movement, end))

    def _movement_pose(self, movement: int) -> MovementPose:
        p1, p2 = self._pose(movement, 0), self._pose(movement, 1)
        o1 = np.array([p1.x(), p1.y()])
        o2 = np.array([p2.x(), p2.y()])
        return MovementPose(o1, p1.theta(), max(float(np.hypot(*(o2 - o1))), 1e-6))

    @property
    def estimates(self) -> dict[str, LandmarkEstimate]:
        """Current estimate per non-reference landmark in the graph (FL)."""
        return dict(self._estimates)

    @property
    def used_movements(self) -> list[int]:
        """Indices of the movements in the graph, in order."""
        return [m.index for m in self._moves]

    @property
    def trajectory_fl(self) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
        """Per movement in the graph, O1 and O2 as (1, 2) arrays in FL."""
        out = []
        for m in self._moves:
            mp = self._movement_pose(m.index)
            out.append((mp.o1_fl[None, :], mp.o2_fl[None, :]))
        return out

    # ------------------------------------------------------------------ placement
    def _sightings(self, obs: MovementObservation) -> Sightings:
        pts, ends, bs = [], [], []
        for end, bmap in enumerate((obs.bearings_o1_rad, obs.bearings_o2_rad)):
            for name, b in bmap.items():
                if name in self._in_graph and math.isfinite(b):
                    pts.append(self._point(name))
                    ends.append(end)
                    bs.append(float(b))
        return Sightings(
            np.array(pts, np.float64).reshape(-1, 2),
            np.array(ends, np.int64),
            np.array(bs, np.float64),
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

    def _place(
        self, obs: MovementObservation, chained: bool, paper_ok: bool
    ) -> tuple[MovementPose, float] | str:
        """The movement's pose by resection, or why it cannot be placed."""
        s = self._sightings(obs)
        n1 = int((s.end == 0).sum())
        n2 = int((s.end == 1).sum())
        need = 2 if chained else 4
        if n1 < 1 or n2 < 1 or n1 + n2 < need:
            return (
                f"too few bearings of mapped landmarks ({n1} at O1, {n2} at O2; "
                f"need one at each and {need} in all)"
            )
        guess = self._reference_guess(obs)
        o1_known = self._movement_pose(self._moves[-1].index).o2_fl if chained else None
        found = resect(s, guesses=[] if guess is None else [guess], o1_known_fl=o1_known)
        if found is None:
            return "no bearing of a mapped landmark at O1"
        robust = 1.4826 * float(np.median(np.abs(found.residuals_rad)))
        if robust > RESECTION_MAX_EPS * self.eps_rad:
            return (
                f"resection does not fit the map (robust residual {math.degrees(robust):.2f} "
                f"deg > {RESECTION_MAX_EPS:g} eps)"
            )
        pos = found.position_std_fl * self.sigma0_rad
        logd = found.log_length_std * self.sigma0_rad
        if pos > RESECTION_MAX_STD_FL or logd > RESECTION_MAX_LOG_STD:
            return (
                f"bearings of mapped landmarks do not determine the movement (std of O1 "
                f"{pos:.2g} FL, of log length {logd:.2g})"
            )
        return found.pose, robust

    # ------------------------------------------------------------------ landmarks
    def _try_enter(self, name: str, new_values: gtsam.Values) -> bool:
        """Initial value for a landmark not in the graph, from its rays or the particles."""
        rays = self._pending.get(name, [])
        origins, dirs = [], []
        for b in rays:
            key = g.pose_key(b.movement, b.end)
            pose = new_values.atPose2(key) if new_values.exists(key) else self._values.atPose2(key)
            origins.append((pose.x(), pose.y()))
            dirs.append(pose.theta() + b.bearing_rad)
        fix = intersect_rays(
            np.array(origins, np.float64).reshape(-1, 2), np.array(dirs), 2.0 * self.eps_rad
        )
        point = None
        if (
            fix is not None
            and fix.parallax_rad >= MIN_RAY_PARALLAX_EPS * self.eps_rad
            and fix.rms_rad <= self.eps_rad
        ):
            point = fix.point_fl
        else:
            belief = self.paper.estimates.get(name)
            if belief is not None:
                spread = math.sqrt(max(float(np.linalg.eigvalsh(belief.cov_fl)[-1]), 0.0))
                if spread <= TIGHT_BELIEF_FL:
                    point = belief.mean_fl
        if point is None:
            return False
        new_values.insert(g.landmark_key(self._lm_index[name]), np.asarray(point, np.float64))
        return True

    # ------------------------------------------------------------------ graph
    def _bearing_noise(self) -> gtsam.noiseModel.Base:
        return g.bearing_noise(self.sigma_model_rad, self.robust)

    def _bearing_factor(self, b: g.Bearing, noise: gtsam.noiseModel.Base) -> gtsam.NonlinearFactor:
        return g.bearing_factor(
            g.pose_key(b.movement, b.end),
            g.landmark_key(self._lm_index[b.landmark]),
            b.bearing_rad,
            noise,
        )

    def _movement_factors(self, m: _Movement, prev: int | None) -> list[gtsam.NonlinearFactor]:
        out = [g.straight_factor(g.pose_key(m.index, 0), g.pose_key(m.index, 1))]
        if m.chained and prev is not None:
            use_turn = self.turn_prior_sigma_rad is not None and m.turn_rad is not None
            out.append(
                g.in_place_factor(
                    g.pose_key(prev, 1),
                    g.pose_key(m.index, 0),
                    m.turn_rad if use_turn else None,
                    self.turn_prior_sigma_rad or 0.0,
                )
            )
        return out

    def _full_graph(self, values: gtsam.Values) -> gtsam.NonlinearFactorGraph:
        """Every factor of the map (for a rebuild), weak priors at ``values``."""
        graph = gtsam.NonlinearFactorGraph()
        l1, l2 = (self._lm_index[r] for r in self.reference)
        for f in g.gauge_factors(g.landmark_key(l1), g.landmark_key(l2)):
            graph.add(f)
        for name in self._in_graph - set(self.reference):
            key = g.landmark_key(self._lm_index[name])
            graph.add(g.weak_point_prior(key, np.asarray(values.atPoint2(key), np.float64)))
        prev: int | None = None
        for m in self._moves:
            for f in self._movement_factors(m, prev):
                graph.add(f)
            for end in (0, 1):
                key = g.pose_key(m.index, end)
                graph.add(g.weak_pose_prior(key, values.atPose2(key)))
            prev = m.index
        noise = self._bearing_noise()
        for b in self._bearings:
            if b.landmark in self._in_graph:
                graph.add(self._bearing_factor(b, noise))
        return graph

    def _rebuild(self, values: gtsam.Values) -> None:
        """A fresh iSAM2 over every factor, from ``values`` refined by Levenberg-Marquardt."""
        graph = self._full_graph(values)
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(100)
        # an indeterminate system keeps the initial values; iSAM2 below still solves from them
        with contextlib.suppress(RuntimeError):
            values = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
        self._isam = self._new_isam()
        self._isam.update(graph, values)
        self._isam.update()
        self._values = self._isam.calculateEstimate()

    def _values_from_particles(self) -> gtsam.Values:
        """Initial values from the initializer's beliefs, keyframes re-placed against them."""
        values = gtsam.Values()
        for name in self._in_graph:
            key = g.landmark_key(self._lm_index[name])
            belief = self.paper.estimates.get(name)
            point = belief.mean_fl if belief is not None else self._point(name)
            values.insert(key, np.asarray(point, np.float64))
        self._values = values
        for k, m in enumerate(self._moves):
            obs = MovementObservation(
                m.index,
                {
                    b.landmark: b.bearing_rad
                    for b in self._bearings
                    if (b.movement, b.end) == (m.index, 0)
                },
                {
                    b.landmark: b.bearing_rad
                    for b in self._bearings
                    if (b.movement, b.end) == (m.index, 1)
                },
            )
            s = self._sightings(obs)
            o1_known = None
            if m.chained and k > 0:
                prev = self._moves[k - 1].index
                o1_known = _pose_o2(values, prev)
            found = resect(s, guesses=[], o1_known_fl=o1_known) if s.bearings_rad.size else None
            pose = found.pose if found is not None else MovementPose(np.zeros(2), 0.0, 0.1)
            for end, p in enumerate(_pose2s(pose)):
                values.insert(g.pose_key(m.index, end), p)
        return values

    # ------------------------------------------------------------------ checks
    def _residuals(self) -> tuple[list[g.Bearing], NDArray[np.float64]]:
        used = [b for b in self._bearings if b.landmark in self._in_graph]
        if not used:
            return used, np.zeros(0)
        poses = [self._pose(b.movement, b.end) for b in used]
        o = np.array([(p.x(), p.y()) for p in poses])
        h = np.array([p.theta() for p in poses])
        pts = np.array([self._point(b.landmark) for b in used])
        d = pts - o
        pred = np.arctan2(d[:, 1], d[:, 0]) - h
        meas = np.array([b.bearing_rad for b in used])
        r = np.angle(np.exp(1j * (meas - pred)))
        return used, r

    def _n_params(self) -> int:
        chains = sum(1 for m in self._moves if m.chained)
        return 2 * (len(self._in_graph) - 2) + 4 * len(self._moves) - 2 * chains

    def _jumped(self, before: dict[str, LandmarkEstimate]) -> str:
        for name, prev in before.items():
            if name not in self._in_graph:
                continue
            step = float(np.hypot(*(self._point(name) - prev.mean_fl)))
            spread = math.sqrt(max(float(np.linalg.eigvalsh(prev.cov_fl)[-1]), 0.0))
            if step > JUMP_FL and step > JUMP_SIGMAS * spread:
                return f"{name} jumped {step:.3f} FL ({step / max(spread, 1e-12):.0f} sigma)"
        return ""

    def _check(self, before: dict[str, LandmarkEstimate]) -> str:
        _, r = self._residuals()
        noise = estimate_noise(r, self._n_params(), self.sigma0_rad)
        if noise.robust_rms_rad > self.eps_rad:
            return f"robust residual RMS {math.degrees(noise.robust_rms_rad):.2f} deg > eps"
        return self._jumped(before)

    def _update_estimates(self) -> None:
        _, r = self._residuals()
        self.noise = estimate_noise(r, self._n_params(), self.sigma0_rad)
        n = self.noise
        if n.dof >= RETUNE_DOF and abs(math.log(n.sigma_rad / self.sigma_model_rad)) > math.log(
            RETUNE_RATIO
        ):
            self.sigma_model_rad = n.sigma_rad
            self._rebuild(self._values)
            _, r = self._residuals()
            self.noise = estimate_noise(r, self._n_params(), self.sigma0_rad)
        scale = (self.noise.sigma_rad / self.sigma_model_rad) ** 2
        out = {}
        for name in sorted(self._in_graph - set(self.reference), key=self._lm_index.__getitem__):
            key = g.landmark_key(self._lm_index[name])
            cov = np.asarray(self._isam.marginalCovariance(key), np.float64) * scale
            out[name] = LandmarkEstimate(self._point(name), 0.5 * (cov + cov.T))
        self._estimates = out

    def add_history(self, name: str, bearings: Sequence[tuple[int, int, float]]) -> None:
        """Bearings of ``name`` from movements already in the graph, known only now.

        An association step names a landmark of a shared class once it is confirmed; its
        earlier bearings ``(movement, end, bearing_rad)`` wait with the landmark's own until it
        enters the graph (movements not in the graph are ignored).
        """
        if name not in self._lm_index or name in self._in_graph:
            return
        placed = {m.index for m in self._moves}
        for movement, end, b in bearings:
            if movement in placed and math.isfinite(b):
                bearing = g.Bearing(movement, end, name, float(b))
                self._bearings.append(bearing)
                self._pending.setdefault(name, []).append(bearing)

    # ------------------------------------------------------------------ one movement
    def process_movement(self, obs: MovementObservation) -> JointMovementResult:
        """Initialize with the paper's filter, place the movement, add its bearings, update."""
        p = self.paper.process_movement(obs)
        res = JointMovementResult(
            obs.index,
            "ok",
            skipped_landmarks=dict(p.skipped_landmarks),
            fused=list(p.fused),
            defensive=list(p.defensive),
            cones_fr=p.cones_fr,
            particles_fr=p.particles_fr,
            particles_fl=p.particles_fl,
            belief_fl=p.belief_fl,
        )
        for name in list(res.skipped_landmarks):
            if name not in self.landmarks:
                continue
            res.skipped_landmarks.pop(name)  # the joint map uses single keyframes too
        clean = MovementObservation(
            obs.index,
            {
                n: float(b)
                for n, b in obs.bearings_o1_rad.items()
                if n in self._lm_index and math.isfinite(b)
            },
            {
                n: float(b)
                for n, b in obs.bearings_o2_rad.items()
                if n in self._lm_index and math.isfinite(b)
            },
            obs.turn_rad,
        )
        chained = bool(self._moves) and self._moves[-1].index == obs.index - 1
        placed = self._place(clean, chained, p.status == "ok")
        if isinstance(placed, str):
            res.status = f"skipped: {placed}"
            res.estimates = self.estimates
            res.noise = self.noise
            return res
        pose, _ = placed
        res.placement = "reference pair" if p.status == "ok" else "resection"
        before = self.estimates
        move = _Movement(obs.index, chained, obs.turn_rad)
        prev = self._moves[-1].index if chained else None
        new_graph = gtsam.NonlinearFactorGraph()
        new_values = gtsam.Values()
        for f in self._movement_factors(move, prev):
            new_graph.add(f)
        for end, p2 in enumerate(_pose2s(pose)):
            key = g.pose_key(obs.index, end)
            new_values.insert(key, p2)
            new_graph.add(g.weak_pose_prior(key, p2))
        self._moves.append(move)
        noise = self._bearing_noise()
        for end, bmap in enumerate((clean.bearings_o1_rad, clean.bearings_o2_rad)):
            for name, b in bmap.items():
                bearing = g.Bearing(obs.index, end, name, b)
                self._bearings.append(bearing)
                if name in self._in_graph:
                    new_graph.add(self._bearing_factor(bearing, noise))
                else:
                    self._pending.setdefault(name, []).append(bearing)
        for name in sorted(self._pending, key=self._lm_index.__getitem__):
            if self._try_enter(name, new_values):
                key = g.landmark_key(self._lm_index[name])
                new_graph.add(g.weak_point_prior(key, np.asarray(new_values.atPoint2(key))))
                for bearing in self._pending.pop(name):
                    new_graph.add(self._bearing_factor(bearing, noise))
                self._in_graph.add(name)
                res.entered.append(name)
        self._isam.update(new_graph, new_values)
        self._isam.update()
        self._values = self._isam.calculateEstimate()
        why = self._check(before)
        if why:
            res.divergence = why
            self.reinitializations += 1
            self._rebuild(self._values_from_particles())
        self._update_estimates()
        res.estimates = self.estimates
        res.noise = self.noise
        mp = self._movement_pose(obs.index)
        res.o1_fl, res.o2_fl = mp.o1_fl[None, :], mp.o2_fl[None, :]
        res.residuals_rad = self._movement_residuals(clean)
        return res

    def _movement_residuals(
        self, obs: MovementObservation
    ) -> dict[str, tuple[float | None, float | None]]:
        out: dict[str, tuple[float | None, float | None]] = {}
        mp = self._movement_pose(obs.index)
        for name in sorted(
            set(obs.bearings_o1_rad) | set(obs.bearings_o2_rad), key=self._lm_index.__getitem__
        ):
            if name not in self._in_graph:
                continue
            pt = self._point(name)
            pair: list[float | None] = []
            for o, bmap in ((mp.o1_fl, obs.bearings_o1_rad), (mp.o2_fl, obs.bearings_o2_rad)):
                b = bmap.get(name)
                if b is None:
                    pair.append(None)
                    continue
                pred = math.atan2(pt[1] - o[1], pt[0] - o[0]) - mp.heading_rad
                pair.append(math.remainder(b - pred, 2.0 * math.pi))
            out[name] = (pair[0], pair[1])
        return out


def _params(pose: MovementPose) -> NDArray[np.float64]:
    return np.array([pose.o1_fl[0], pose.o1_fl[1], pose.heading_rad, math.log(pose.length_fl)])


def _pose2s(pose: MovementPose) -> tuple[gtsam.Pose2, gtsam.Pose2]:
    o2 = pose.o2_fl
    return (
        gtsam.Pose2(float(pose.o1_fl[0]), float(pose.o1_fl[1]), pose.heading_rad),
        gtsam.Pose2(float(o2[0]), float(o2[1]), pose.heading_rad),
    )


def _pose_o2(values: gtsam.Values, movement: int) -> NDArray[np.float64]:
    p = values.atPose2(g.pose_key(movement, 1))
    return np.array([p.x(), p.y()])
