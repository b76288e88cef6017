"""The joint estimator: one factor graph over every keyframe and landmark, updated by iSAM2.

Per movement: the paper's filter (:class:`pipeline.slam.BearingSlam`) runs first as the
initializer. The map starts (bootstrap) with a batch solve of the first movements whose
reference pair can be triangulated, once their bearings over-determine them; later movements are
placed by resection against the landmarks already in the graph (L1, L2 included), and a movement
that cannot be placed yet waits and is tried again as the map grows. Every bearing of a placed
movement becomes a bearing factor (Huber loss) or waits until its landmark enters the graph
(rays from placed keyframes that meet with enough parallax, or a tight particle belief of the
initializer); iSAM2 updates the map; the bearing noise is estimated from the residuals; a
divergence check re-initializes the graph from the initializer's particles; a map stuck away
from its optimum (a reference landmark's bearings mostly rejected, lengths that disagree with the
driven distances) is solved again from its whole record and kept when it explains the record
better. Covariances are
iSAM2's marginals scaled by the estimated noise. Maths and departures from the paper:
docs/method.md.

:class:`JointSlam` composes the parts for one movement, each in its own module:

- :mod:`pipeline.joint.state`: the settings, the movements and the one state object
  (:class:`~pipeline.joint.state.MapState`) a rollback restores;
- :mod:`pipeline.joint.placement`: where a movement is placed (bootstrap plan, resection,
  waiting movements);
- :mod:`pipeline.joint.mapgraph`: the graph bookkeeping (iSAM2, values, factors, bearing table,
  bootstrap batch solve, rebuild, estimates);
- :mod:`pipeline.joint.robustness`: outlier rejection, reseating, the divergence check, the
  rollback and the evidence that the map is stuck;
- :mod:`pipeline.joint.window`: the oldest movements marginalized out of the graph once it
  holds :data:`~pipeline.joint.window.WINDOW_STRIDE` movements more than the window.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import replace

import gtsam
import numpy as np

from data_schemas.errors import EstimationError
from pipeline.crb import truncated_gaussian_std
from pipeline.estimate import LandmarkEstimate
from pipeline.fusion import PAPER_N_L, PAPER_N_R
from pipeline.geometry import KeyframePose, MovementPose
from pipeline.joint import graph as g
from pipeline.joint import placement, robustness
from pipeline.joint.frame_spread import frame_spread_cov
from pipeline.joint.mapgraph import CAREFUL_MOVEMENTS, MapGraph, pose2s
from pipeline.joint.noise import NoiseEstimate, robust_std
from pipeline.joint.result import JointMovementResult
from pipeline.joint.state import JointSettings, MapState, Movement
from pipeline.joint.table import by_landmark
from pipeline.joint.window import (
    DEFAULT_WINDOW,
    MIN_WINDOW,
    due,
    marginalize,
    marginalize_oldest,
)
from pipeline.priors import PriorName
from pipeline.slam import BearingSlam, MovementObservation, MovementStatus, Placement, skipped

#: A map found stuck (:func:`pipeline.joint.robustness.stuck`) is solved again only once it
#: holds this many times the movements it held at the last try (each try fits the whole record).
MEND_GROWTH = 1.5
#: ... and while it holds at most this many movements (a map goes wrong where it starts; a
#: batch fit of a long record costs seconds), none of them marginalized.
MEND_MAX_MOVEMENTS = CAREFUL_MOVEMENTS


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
        eps), or when a landmark jumps (:func:`pipeline.joint.robustness.jumped`).
    window : int or None
        Movements kept in the graph (at least :data:`pipeline.joint.window.MIN_WINDOW`);
        older ones are marginalized into a prior on the rest (:mod:`pipeline.joint.window`),
        so that the cost per movement does not grow with the log. None keeps every movement.

    Attributes
    ----------
    paper : BearingSlam
        The initializer.
    settings : JointSettings
        The settings above but the window, as the parts of the estimator take them.
    window : int or None
        As given.
    reinitializations : int
        How many times the map diverged and was re-initialized from the particles.
    mends : list of (int, str)
        The movements after which the map was found stuck and solved again from its whole
        record (the solve kept), with why it was found stuck.
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
        window: int | None = DEFAULT_WINDOW,
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
        if window is not None and window < MIN_WINDOW:
            raise EstimationError(f"window must be at least {MIN_WINDOW} movements, got {window}")
        self.window = window
        eps_rad = float(vision_error_rad)
        self.settings = JointSettings(
            landmarks=tuple(self.paper.landmarks),
            reference=reference,
            eps_rad=eps_rad,
            sigma0_rad=truncated_gaussian_std(eps_rad),
            robust=robust,
            turn_prior_sigma_rad=turn_prior_sigma_rad,
            distance_prior_rel=distance_prior_rel,
            divergence_rms_rad=eps_rad if divergence_rms_rad is None else divergence_rms_rad,
        )
        self._lm_index = self.settings.index
        self._state = MapState.empty(self.settings)
        self._map = MapGraph(self.settings)
        self._placer = placement.Placer(self.settings)
        self.reinitializations = 0
        self.mends: list[tuple[int, str]] = []
        self._mend_tried = 0  # movements placed at the last try to mend the map

    # ------------------------------------------------------------------ the map as it is
    @property
    def noise(self) -> NoiseEstimate | None:
        """The bearing noise estimated from the map's residuals (None before a map)."""
        return self._state.noise

    @property
    def sigma_model_rad(self) -> float:
        """The bearing std (rad) the bearing factors are weighted with now."""
        return self._state.sigma_model_rad

    @property
    def estimates(self) -> dict[str, LandmarkEstimate]:
        """Current estimate per non-reference landmark in the graph (FL), as the map reports it:
        the point, and the linearized marginal (:attr:`marginals`) with the frame's turn and
        scale about the reference pair carried to second order
        (:func:`~pipeline.joint.frame_spread.frame_spread_cov`)."""
        return {
            name: LandmarkEstimate(e.mean_fl, frame_spread_cov(e.mean_fl, e.cov_fl))
            for name, e in self._state.estimates.items()
        }

    @property
    def marginals(self) -> dict[str, LandmarkEstimate]:
        """Per non-reference landmark in the graph: the point and iSAM2's marginal, scaled by
        the estimated noise (FL). What association predicts bearings with: a turn of the frame
        moves the keyframes with the landmarks, so a prediction from a keyframe keeps it to first
        order, as the keyframes' covariances do."""
        return dict(self._state.estimates)

    @property
    def unit_m(self) -> float | None:
        """The map's unit |L1 L2| in metres, estimated through the distance prior (None without
        it, or before a movement with a distance is in the map)."""
        return self._map.unit_m()

    @property
    def bearing_scatter(self) -> dict[str, tuple[int, float]]:
        """Per non-reference landmark in the map: how many bearings it has there and how widely
        they scatter about it, as the robust scale of their residuals (1.4826 times their median
        absolute value) over the map's bearing noise (:attr:`noise`). Near 1 for a landmark whose
        rays meet at one point; well above for bearings of several landmarks given one name."""
        if self._state.noise is None:
            return {}
        sigma = max(self._state.noise.sigma_rad, 1e-12)
        skip = self.settings.reference_indices()
        live = by_landmark(self._map.table, self._map.residuals(), skip)
        frozen = self._state.frozen_bearings
        out = {}
        for j in sorted({*live, *np.unique(frozen.landmark).tolist()} - set(skip)):
            v = np.concatenate(
                [live.get(j, np.zeros(0)), frozen.residual_rad[frozen.landmark == j]]
            )
            out[self.settings.landmarks[j]] = (v.size, robust_std(v) / sigma)
        return out

    @property
    def used_movements(self) -> list[int]:
        """Indices of the movements placed in the map (in the graph or marginalized), in order."""
        return sorted([*self._state.placed, *self._state.frozen])

    @property
    def waiting_movements(self) -> list[int]:
        """Indices of the movements not placed (yet)."""
        return sorted(self._state.waiting)

    def movement_poses(self) -> dict[int, MovementPose]:
        """Every movement placed in the map, by index (in order): O1, the heading of O1 and the
        distance O1 -> O2 (FL), as iSAM2 has them now (a marginalized movement: where it was
        when it left the graph)."""
        out = {}
        for k in self.used_movements:
            frozen = self._state.frozen.get(k)
            if frozen is None:
                out[k] = self._map.movement_pose(k)
                continue
            (x1, y1, heading), (x2, y2, _) = frozen.poses
            out[k] = MovementPose.from_ends(np.array([x1, y1]), heading, np.array([x2, y2]))
        return out

    def keyframe_poses(self) -> dict[tuple[int, int], KeyframePose]:
        """Every keyframe in the graph, ``(movement, end)`` (end 0: O1, 1: O2), as iSAM2 has it
        now: position and heading (FL) and the covariance of its tangent ``(x, y, heading)``
        in the keyframe's own frame (FL, rad), scaled by the estimated noise as the landmarks'
        covariances are. A keyframe whose marginal iSAM2 cannot give (an indeterminate
        system) is left out. A marginalized movement's keyframes are as they were when it left
        the graph (pose and covariance then, scaled by the noise estimated now)."""
        scale = self._state.covariance_scale()
        out = {}
        for k, frozen in sorted(self._state.frozen.items()):
            for end, ((x, y, heading), cov) in enumerate(
                zip(frozen.poses, frozen.covs, strict=True)
            ):
                if cov is not None:
                    out[k, end] = KeyframePose(np.array([x, y]), heading, cov * scale)
        out.update(self._map.keyframe_poses(sorted(self._state.placed), scale))
        return out

    def _belief(self, name: str) -> LandmarkEstimate | None:
        """The initializer's (the paper's filter's) belief about a landmark, if it has one."""
        return self.paper.estimates.get(name)

    # ------------------------------------------------------------------ names given late
    def forget(self, name: str) -> None:
        """Take landmark ``name`` out of the map with every bearing given to it so far (an
        association step found its name wrong); :meth:`add_history` may give it again."""
        if name in self.settings.reference or name not in self._lm_index:
            return
        for m in (*self._state.placed.values(), *self._state.waiting.values()):
            m.bearings[:] = [b for b in m.bearings if b.landmark != name]
        self._state.pending.pop(name, None)
        self._state.rejected = {b for b in self._state.rejected if b.landmark != name}
        for frozen in self._state.frozen.values():  # shared with the snapshot: a new list
            frozen.movement.bearings[:] = [
                b for b in frozen.movement.bearings if b.landmark != name
            ]
        self._state.frozen_bearings = self._state.frozen_bearings.without(self._lm_index[name])
        self.paper.forget(name)
        self._state.estimates.pop(name, None)
        if name in self._state.in_graph:
            self._state.in_graph.discard(name)
            self._map.retable(self._state)
            values = gtsam.Values(self._map.values)
            if self._state.prior is not None:  # its bearings' part of the prior stays in it
                self._state.prior = marginalize(
                    [self._state.prior], values, [self._map.key(name)]
                ).prior
            values.erase(self._map.key(name))
            self._map.rebuild(self._state, values)
            self._map.update_estimates(self._state)

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

    def rebear(
        self,
        bearings: Mapping[str, Sequence[tuple[int, int, float]]],
        moved: Mapping[int, MovementPose] | None = None,
    ) -> None:
        """Give each landmark of ``bearings`` (in the graph) exactly these bearings
        ``(movement, end, bearing_rad)`` of the placed movements in place of the ones it had
        there (once the log is processed, association with the final map found them), and
        solve the map again from its current values (one rebuild: the landmarks keep their
        points as initial values, so a landmark that holds keyframes in place is never taken
        out). Landmarks not in the graph, and other movements' bearings, are ignored.

        ``moved``: placed movements the solve starts from these poses (FL) instead, their
        bearings rejected until now counted again (once the log is processed, movements the
        map held misplaced and association placed again by matching)."""
        names = {n for n in bearings if n in self._state.in_graph}
        again = {m: p for m, p in (moved or {}).items() if m in self._state.placed}
        if not (names or again) or not self._state.placed:
            return
        for m in self._state.placed.values():
            m.bearings[:] = [b for b in m.bearings if b.landmark not in names]
        self._state.rejected = {
            b for b in self._state.rejected if b.landmark not in names and b.movement not in again
        }
        for name in sorted(names):
            for movement, end, b in bearings[name]:
                placed = self._state.placed.get(movement)
                if placed is not None and math.isfinite(b):
                    placed.bearings.append(g.Bearing(movement, end, name, float(b)))
        values = gtsam.Values(self._map.values)
        for movement, pose in again.items():
            for end, pose2 in enumerate(pose2s(pose)):
                values.update(g.pose_key(movement, end), pose2)
        self._map.retable(self._state)
        self._map.rebuild(self._state, values)
        robustness.reject_outliers(self._state, self._map)
        self._map.update_estimates(self._state)

    def settle(self) -> list[str]:
        """Enter the landmarks whose bearings wait (given by :meth:`add_history` after the
        last movement) and update the map, without a movement; their names."""
        if not self._state.placed or not self._state.pending:
            return []
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        entered = self._map.enter_pending(self._state, graph, values, self._belief)
        if entered:
            self._map.update(graph, values)
            robustness.reject_outliers(self._state, self._map)
            self._map.update_estimates(self._state)
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
        mapped = self._state.in_graph - set(self.settings.reference)
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
        m = Movement(obs.index, obs.turn_rad, bearings, obs.distance_m)
        if self._map.careful and len(self._state.placed) >= CAREFUL_MOVEMENTS:
            # the map is determined: plain steps from now on
            self._map.rebuild(self._state, self._map.values)
        if due(self._state, self.window):
            marginalize_oldest(self._state, self._map, self.window or 0)
        snap = robustness.snapshot(self._state, self._map)  # the map before the movement
        self._state.waiting[obs.index] = m
        before = self.marginals
        placed: list[int] = []
        why = ""
        if not self._state.placed:
            boot = self._bootstrap()
            if isinstance(boot, str):
                why = boot
            else:
                placed = boot
                graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
                self._map.enter_pending(self._state, graph, values, self._belief)
                self._map.update(graph, values)
        if self._state.placed:
            placed += self._placer.place_waiting(self._state, self._map, self._belief)
        if obs.index not in self._state.placed:
            reason = why or self._placer.place(self._state, self._map, m)
            res.status = skipped(reason if isinstance(reason, str) else "not placed")
        if not placed:
            res.estimates, res.noise = self.estimates, self._state.noise
            return res
        res.placement = (
            Placement.REFERENCE_PAIR if p.status == MovementStatus.OK else Placement.RESECTION
        )
        res.also_placed = [k for k in placed if k != obs.index]
        divergence = robustness.divergence(self._state, self._map, before)
        if divergence:
            res.divergence = divergence
            self.reinitializations += 1
            values = placement.values_from_beliefs(self._state, self._map, self._belief)
            self._map.rebuild(self._state, values)
            still = robustness.misfit(
                self._state, self._map, max(self.settings.eps_rad, self.settings.divergence_rms_rad)
            )
            if still:
                return self._roll_back(res, snap, m, divergence, still)
        robustness.reject_outliers(self._state, self._map)
        if robustness.reseat_landmarks(self._state, self._map, self.paper.noise.r_max):
            robustness.reject_outliers(self._state, self._map)
        mended = self._mend()
        if mended:
            self.mends.append((obs.index, mended))
            res.solved_again = mended
        self._map.update_estimates(self._state)
        res.estimates, res.noise = self.estimates, self._state.noise
        if obs.index in self._state.placed:
            mp = self._map.movement_pose(obs.index)
            res.o1_fl, res.o2_fl = mp.o1_fl[None, :], mp.o2_fl[None, :]
            res.residuals_rad = self._movement_residuals(m)
        else:
            res.placement = Placement.NONE
        return res

    def _bootstrap(self) -> list[int] | str:
        """Start the map: one batch solve over the waiting movements with a reference frame
        (the movements placed), or why not (the movements wait, the state as it was)."""
        plan = placement.bootstrap_plan(self.settings, self._state)
        if isinstance(plan, str):
            return plan
        before = self._state.copy()
        started = self._map.bootstrap(self._state, plan.guesses, plan.seeds_fl)
        if isinstance(started, str):
            self._state = before
        return started

    def _mend(self) -> str:
        """Solve the map again from its whole record when it looks stuck away from its optimum
        (:func:`pipeline.joint.robustness.stuck`; tried again only as the map grows by
        :data:`MEND_GROWTH`, up to :data:`MEND_MAX_MOVEMENTS` movements, none marginalized).

        Two solves, each with every bearing back in, Levenberg-Marquardt over the whole graph,
        then outlier rejection and reseating: one from the map as it is, one from values that
        owe nothing to it (:func:`pipeline.joint.placement.record_values`). The one that
        explains the record best (:func:`pipeline.joint.robustness.record_error`) replaces the
        map if it explains it better than the map does and has not collapsed
        (:func:`pipeline.joint.robustness.collapsed`: a landmark where the robot stood fits any
        bearing of it); why the map was stuck, or empty (nothing changed)."""
        state = self._state
        n = len(state.placed)
        if state.frozen or n > MEND_MAX_MOVEMENTS or n < MEND_GROWTH * self._mend_tried:
            return ""
        why = robustness.stuck(state, self._map)
        if not why:
            return ""
        self._mend_tried = n
        best = (robustness.record_error(state, self._map), state, self._map)
        for from_record in (False, True):
            trial = state.copy()
            trial.rejected = set()
            graph = MapGraph(self.settings)
            graph.values = self._map.values
            graph.retable(trial)
            values = placement.record_values(trial, graph) if from_record else graph.values
            if values is None:
                continue
            graph.rebuild(trial, values)
            robustness.reject_outliers(trial, graph)
            if robustness.reseat_landmarks(trial, graph, self.paper.noise.r_max):
                robustness.reject_outliers(trial, graph)
            error = robustness.record_error(trial, graph)
            if error < best[0] and not robustness.collapsed(trial, graph):
                best = (error, trial, graph)
        if best[1] is state:
            return ""
        self._state, self._map = best[1], best[2]
        self._placer = placement.Placer(self.settings)  # its memory is of the map before
        return why

    def _roll_back(
        self,
        res: JointMovementResult,
        snap: robustness.Snapshot,
        m: Movement,
        divergence: str,
        still: str,
    ) -> JointMovementResult:
        """The map as it was before movement ``m``, which is refused when there was a map;
        without one, every movement waits for the bootstrap to try again with more."""
        self._state = robustness.roll_back(snap, self._map)
        if not self._state.placed:
            self._state.waiting[m.index] = m
        res.status = skipped(
            f"the map diverged with it ({divergence}) and re-initialization from the "
            f"particles did not fit ({still}); the map is kept as before it"
        )
        res.placement, res.also_placed = Placement.NONE, []
        res.estimates, res.noise = self.estimates, self._state.noise
        return res

    def _movement_residuals(self, m: Movement) -> dict[str, tuple[float | None, float | None]]:
        """Bearing residuals (rad) of one placed movement, per landmark in the graph: its rows
        of the bearing table at the map as it is (each at its own keyframe)."""
        table, r = self._map.table, self._map.residuals()
        out: dict[str, list[float | None]] = {}
        for i in np.flatnonzero(table.slot // 2 == m.index):
            b = table.rows[i]
            out.setdefault(b.landmark, [None, None])[b.end] = float(r[i])
        return {
            n: (v[0], v[1]) for n, v in sorted(out.items(), key=lambda kv: self._lm_index[kv[0]])
        }
