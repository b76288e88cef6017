"""Placement of a movement in the joint map: where its keyframes are, before its bearings enter.

The first movements are placed in the reference pair's frame (:func:`reference_guess`: the
paper's two-view triangulation of L1 and L2) and solved together by the bootstrap
(:func:`bootstrap_plan` says which and with which first landmark points; the batch solve is
:meth:`pipeline.joint.mapgraph.MapGraph.bootstrap`). Every later movement is placed by
resection (:func:`pipeline.geometry.resect`) against the landmarks in the graph
(:meth:`Placer.place`), chained on the previous movement's end when that one is placed; a
movement the bearings do not determine waits, and :meth:`Placer.place_waiting` tries the waiting
ones again as the map grows. After a divergence, :func:`values_from_beliefs` places every
movement again against the initializer's landmark beliefs; a map solved again from its whole
record starts from :func:`record_values` (batch least squares' landmarks, movements resected).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import gtsam
import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad
from data_schemas.errors import EstimationError
from pipeline.batch_ls import batch_least_squares
from pipeline.estimate import LandmarkEstimate
from pipeline.frame_change import to_fl
from pipeline.geometry import (
    MovementPose,
    Sightings,
    determinacy,
    pose_params,
    resect,
    triangulate_fr,
)
from pipeline.joint import graph as g
from pipeline.joint.mapgraph import MapGraph, pose2s
from pipeline.joint.noise import robust_std
from pipeline.joint.robustness import REJECT_EPS
from pipeline.joint.state import JointSettings, MapState, Movement
from pipeline.slam import MovementObservation

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

#: What a movement saw of the map: whether its start is pinned (previous movement placed), how
#: many bearings it has, and the mapped landmarks of its bearings (in order).
_Seen = tuple[bool, int, tuple[str, ...]]


def reach(s: Sightings, o1_fl: NDArray[np.float64]) -> float:
    """Median distance (FL) of the sighted landmarks from O1 (2,)."""
    return float(np.median(np.hypot(*(s.points_fl - o1_fl).T)))


def sightings(state: MapState, graph: MapGraph, m: Movement) -> Sightings:
    """The bearings of ``m`` whose landmark is in the graph, with the landmarks' positions."""
    used = [b for b in m.bearings if b.landmark in state.in_graph]
    return Sightings(
        np.array([graph.point(b.landmark) for b in used], np.float64).reshape(-1, 2),
        np.array([b.end for b in used], np.int64),
        np.array([b.bearing_rad for b in used], np.float64),
    )


def reference_guess(reference: tuple[str, str], obs: MovementObservation) -> MovementPose | None:
    """The paper's frame: the movement seen through the reference pair's triangulation."""
    l1, l2 = reference
    b1, b2 = obs.bearings_o1_rad, obs.bearings_o2_rad
    if not all(r in b1 and r in b2 for r in reference):
        return None
    s1 = triangulate_fr(b1[l1], b2[l1])
    s2 = triangulate_fr(b1[l2], b2[l2])
    if s1 is None or s2 is None:
        return None
    o = to_fl(np.array([[0.0, 0.0], [1.0, 0.0]]), s1, s2)
    d = o[1] - o[0]
    return MovementPose(o[0], math.atan2(d[1], d[0]), float(np.hypot(*d)))


def paper_frame(reference: tuple[str, str], eps_rad: float, obs: MovementObservation) -> bool:
    """Whether both reference landmarks have the parallax the paper asks (over 2 eps)."""
    b1, b2 = obs.bearings_o1_rad, obs.bearings_o2_rad
    return all(
        r in b1 and r in b2 and abs(wrap_rad(b2[r] - b1[r])) > 2.0 * eps_rad for r in reference
    )


@dataclass(frozen=True)
class BootstrapPlan:
    """The movements and landmarks the bootstrap solves together.

    Attributes
    ----------
    guesses : dict of int to MovementPose
        Waiting movements that see the reference pair with parallax, placed in its frame.
    seeds_fl : dict of str to (2,) float
        Other landmarks seen from both ends of one of them: the median of their two-view
        triangulations (FL).
    """

    guesses: dict[int, MovementPose]
    seeds_fl: dict[str, NDArray[np.float64]]


def bootstrap_plan(settings: JointSettings, state: MapState) -> BootstrapPlan | str:
    """What the map starts with (the waiting movements with a reference frame, the landmarks
    they triangulate), or why it cannot start yet (too few bearings for a check on the fit)."""
    guesses = {}
    for k in sorted(state.waiting):
        guess = reference_guess(settings.reference, state.waiting[k].observation())
        if guess is not None:
            guesses[k] = guess
    if not guesses:
        return "no movement sees the reference pair with parallax yet (the map starts there)"
    seeds: dict[str, list[NDArray[np.float64]]] = {}
    for k, guess in guesses.items():
        obs = state.waiting[k].observation()
        for name, b1 in obs.bearings_o1_rad.items():
            b2 = obs.bearings_o2_rad.get(name)
            if name in settings.reference or b2 is None:
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
        for b in state.waiting[k].bearings
        if b.landmark in settings.reference or b.landmark in seeds
    )
    n_links = sum(1 for k in guesses if k - 1 in guesses)
    dof = n_bearings - (4 * len(guesses) - 2 * n_links + 2 * len(seeds))
    paper_frames = all(
        paper_frame(settings.reference, settings.eps_rad, state.waiting[k].observation())
        for k in guesses
    )
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
    seeds_fl = {name: np.median(np.array(pts), axis=0) for name, pts in seeds.items()}
    return BootstrapPlan(guesses, seeds_fl)


class Placer:
    """Places movements by resection against the map, remembering the ones that were not
    determined (so as not to resect them again while nothing they see has changed).

    Parameters
    ----------
    settings : JointSettings
        The estimator's settings.
    """

    def __init__(self, settings: JointSettings) -> None:
        self.settings = settings
        # movements the bearings did not determine: what they saw, where the fit put them
        self._undetermined: dict[int, tuple[_Seen, NDArray[np.float64], NDArray[np.bool_]]] = {}

    def place(
        self, state: MapState, graph: MapGraph, m: Movement
    ) -> tuple[MovementPose, set[g.Bearing]] | str:
        """The movement's pose by resection against the map and its bearings beyond
        :data:`pipeline.joint.robustness.REJECT_EPS` eps of it (wrong detections), or why it
        cannot be placed.

        A movement the bearings did not determine is not resected again while it sees the same
        mapped landmarks with the same bearings and the same start (placed previous movement
        or not), as long as they still clearly (:data:`UNDETERMINED_MARGIN`) do not determine
        it at the pose last fitted against the map as it is now. A fit that determines nothing
        at all (singular) is no such evidence: a degenerate local optimum looks the same.
        """
        eps = self.settings.eps_rad
        used = [b for b in m.bearings if b.landmark in state.in_graph]
        s = sightings(state, graph, m)
        n1 = int((s.end == 0).sum())
        n2 = int((s.end == 1).sum())
        chained = m.index - 1 in state.placed
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
                reach(s, x[:2]),
                margin=UNDETERMINED_MARGIN,
            )
            if why is not None:
                return why
        guess = reference_guess(self.settings.reference, m.observation())
        o1_known = graph.movement_pose(m.index - 1).o2_fl if chained else None
        found = resect(
            s,
            guesses=[] if guess is None else [guess],
            o1_known_fl=o1_known,
            outlier_rad=RESECTION_MAX_EPS * eps,
        )
        if found is None:
            return "no bearing of a mapped landmark at O1"
        robust = robust_std(found.residuals_rad)
        if robust > RESECTION_MAX_EPS * eps:
            return (
                f"resection does not fit the map (robust residual {math.degrees(robust):.2f} "
                f"deg > {RESECTION_MAX_EPS:g} eps)"
            )
        why = self._undetermined_why(
            found.position_std_fl, found.log_length_std, reach(s, found.pose.o1_fl)
        )
        if why is not None:
            if math.isfinite(found.position_std_fl) and math.isfinite(found.log_length_std):
                self._undetermined[m.index] = (seen, pose_params(found.pose), found.inliers)
            return why
        self._undetermined.pop(m.index, None)
        far = np.abs(found.residuals_rad) > REJECT_EPS * eps
        return found.pose, {b for b, out in zip(used, far, strict=True) if out}

    def _undetermined_why(
        self, position_std: float, log_length_std: float, reach_fl: float, *, margin: float = 1.0
    ) -> str | None:
        """Why bearings do not determine a movement, from the stds of its fit for a bearing
        noise of 1 rad (:func:`pipeline.geometry.determinacy`) and the median distance
        (FL) of the landmarks from O1 (None when they do, within ``margin`` times the bounds)."""
        sigma0 = self.settings.sigma0_rad
        rel = position_std * sigma0 / max(reach_fl, 1e-9)
        logd = log_length_std * sigma0
        if rel > margin * RESECTION_MAX_REL_STD or logd > margin * RESECTION_MAX_LOG_STD:
            return (
                f"bearings of mapped landmarks do not determine the movement (relative std of "
                f"O1 {rel:.2g}, of log length {logd:.2g})"
            )
        return None

    def place_waiting(
        self,
        state: MapState,
        graph: MapGraph,
        belief_of: Callable[[str], LandmarkEstimate | None],
    ) -> list[int]:
        """Place every waiting movement the map can place now (again while any is placed),
        each with one iSAM2 update that also enters the landmarks it brings (first points from
        their rays, else from the initializer's belief, ``belief_of(name)``)."""
        placed: list[int] = []
        progress = True
        while progress and state.waiting:
            progress = False
            for k in sorted(state.waiting):
                m = state.waiting[k]
                found = self.place(state, graph, m)
                if isinstance(found, str):
                    continue
                new, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
                graph.add_movement(state, m, found[0], new, values, found[1])
                graph.enter_pending(state, new, values, belief_of)
                graph.update(new, values)
                placed.append(k)
                progress = True
        return placed


def values_from_beliefs(
    state: MapState, graph: MapGraph, belief_of: Callable[[str], LandmarkEstimate | None]
) -> gtsam.Values:
    """Initial values from the initializer's landmark beliefs, ``belief_of(name)`` (the
    graph's estimate for a landmark without one), every placed movement resected again
    against them (chained on the previous one's end when that is placed; its pose in the
    graph when resection fails)."""
    values = gtsam.Values()
    for name in state.in_graph:
        belief = belief_of(name)
        point = belief.mean_fl if belief is not None else graph.point(name)
        values.insert(graph.key(name), np.asarray(point, np.float64))
    old = graph.values
    graph.values = values  # the sightings below read the landmarks from the new values
    for k in sorted(state.placed):
        m = state.placed[k]
        s = sightings(state, graph, m)
        o1_known = graph.movement_pose(k - 1, values).o2_fl if k - 1 in state.placed else None
        found = (
            resect(
                s,
                guesses=[],
                o1_known_fl=o1_known,
                outlier_rad=RESECTION_MAX_EPS * graph.settings.eps_rad,
            )
            if s.bearings_rad.size
            else None
        )
        pose = found.pose if found is not None else graph.movement_pose(k, old)
        for end, p in enumerate(pose2s(pose)):
            values.insert(g.pose_key(k, end), p)
    if old.exists(g.SCALE_KEY):
        values.insert(g.SCALE_KEY, old.atVector(g.SCALE_KEY))
    return values


def record_values(state: MapState, graph: MapGraph) -> gtsam.Values | None:
    """Initial values for the map solved again from its whole record, owing nothing to the map
    as it is: the landmarks at batch least squares' fit of the placed movements' bearings
    (:func:`pipeline.batch_ls.batch_least_squares`: each movement in its reference pair's
    two-view frame, landmarks at the median of their triangulations, one least-squares solve),
    every movement resected against them (:func:`values_from_beliefs`; a landmark the fit does
    not place keeps its point in the graph). None when no placed movement triangulates the
    reference pair."""
    observations = [state.placed[k].observation() for k in sorted(state.placed)]
    try:
        points = batch_least_squares(
            observations, graph.settings.landmarks, graph.settings.reference
        )
    except EstimationError:
        return None
    unit = np.eye(2)  # only the mean is read

    def fitted(name: str) -> LandmarkEstimate | None:
        p = points.get(name)
        return None if p is None or not np.isfinite(p).all() else LandmarkEstimate(p, unit)

    return values_from_beliefs(state, graph, fitted)
