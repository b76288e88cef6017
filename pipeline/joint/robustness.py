"""Robustness of the joint map: wrong detections out, wrong landmarks moved, divergence undone.

After each update the bearings far from the map are taken out of the graph and rejected ones
that fit again are put back (:func:`reject_outliers`); a landmark that lost most of its bearings
that way, or that lost some and stands out of every vision cone's reach, is moved to where its
rays meet (:func:`reseat_landmarks`). A map whose residuals are
out of bounds or whose landmark jumped counts as diverged (:func:`divergence`); when
re-initialization does not bring it back, the map returns to the :class:`Snapshot` taken before
the movement (:func:`roll_back`). A map whose own record says it is stuck away from its optimum
(:func:`stuck`: a reference landmark's bearings mostly rejected, or movement lengths that
disagree with the driven distances) is solved again from the whole record by the estimator, and
the solve kept when its :func:`record_error` is lower. Every function but :func:`out_of_reach`
(points in, a verdict out) takes the map's state and graph as arguments.
"""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass

import gtsam
import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad
from pipeline.estimate import LandmarkEstimate
from pipeline.geometry import intersect_rays, predicted_bearings, widest_std
from pipeline.joint import graph as g
from pipeline.joint.mapgraph import MIN_RAY_PARALLAX_EPS, MapGraph
from pipeline.joint.noise import robust_rms
from pipeline.joint.state import MapState
from pipeline.joint.table import by_landmark

#: A landmark "jumps" when one update moves it by more than this (FL) ...
JUMP_FL = 0.1
#: ... and by more than this many standard deviations of its previous estimate.
JUMP_SIGMAS = 5.0
#: A bearing this many eps from the map is taken out of the graph (the error bound is eps).
REJECT_EPS = 2.0
#: A rejected bearing this close (eps) to the map is put back.
READMIT_EPS = 1.5
#: More than this fraction of the bearings beyond REJECT_EPS eps: the map is wrong, not them.
MAX_REJECT_FRACTION = 0.1
#: A landmark with at least this many rejected bearings, and more rejected than kept (or out
#: of reach, :func:`out_of_reach`), is put where its rays meet (its estimate is wrong, not its
#: bearings).
RESEAT_MIN_REJECTED = 3
#: A reference landmark with at least this many bearings in the map, more than half of them
#: rejected, leaves the map's frame resting on bearings that do not fit it: the map is stuck.
STUCK_MIN_REFERENCE_BEARINGS = 6
#: With the distance prior, at least this many movements with a driven distance whose lengths
#: in the map disagree with it by a median of more than :data:`STUCK_DISTANCE_SIGMAS` times the
#: prior's relative std (in log length, about the map's scale): the map's unit is stuck.
STUCK_MIN_DISTANCES = 3
STUCK_DISTANCE_SIGMAS = 3.0


def reject_outliers(state: MapState, graph: MapGraph) -> None:
    """Take out bearings beyond :data:`REJECT_EPS` eps of the map; put back rejected ones
    within :data:`READMIT_EPS` eps.

    The method's bearing error is bounded by eps, so a residual that far is a wrong
    detection (the Huber loss only bounds its pull)."""
    eps = graph.settings.eps_rad
    r = np.abs(graph.residuals())
    rejected = graph.table.rejected
    out = graph.table.select(~rejected & (r > REJECT_EPS * eps))
    back = graph.table.select(rejected & (r <= READMIT_EPS * eps))
    if out or back:
        graph.set_rejected(state, out, back)


def out_of_reach(
    point_fl: NDArray[np.float64],
    ends_fl: NDArray[np.float64],
    starts_fl: NDArray[np.float64],
    r_max: float,
) -> bool:
    """Whether a landmark stands beyond every vision cone that holds it: farther than ``r_max``
    movement lengths (the impartial prior's range bound, :data:`pipeline.priors.R_MAX_FR`)
    from the keyframe of each of its bearings.

    Parameters
    ----------
    point_fl : (2,) array
        The landmark's point (FL).
    ends_fl, starts_fl : (k, 2) arrays
        Each bearing's keyframe position and the other end of its movement (FL).
    r_max : float
        Range bound in movement lengths.
    """
    range_fl = np.hypot(*(point_fl - ends_fl).T)
    length_fl = np.hypot(*(ends_fl - starts_fl).T)
    return bool((range_fl > r_max * length_fl).all())


def reseat_landmarks(state: MapState, graph: MapGraph, r_max: float) -> list[str]:
    """Landmarks moved to where their rays meet, when most of their bearings were rejected
    (the landmark is wrong, not its bearings: it entered from a poor first estimate), or when
    some were and it stands beyond the reach of every cone that holds it (:func:`out_of_reach`
    with ``r_max`` movement lengths: impossible under the impartial prior, a map that ran away
    along near-parallel rays); the map is then rebuilt with those bearings back in."""
    settings, table = graph.settings, graph.table
    eps = settings.eps_rad
    n_out_of = np.bincount(table.landmark[table.rejected], minlength=len(settings.landmarks))
    if not (n_out_of >= RESEAT_MIN_REJECTED).any():  # no landmark has enough out (most often)
        return []
    skip = settings.reference_indices()
    n_rows = by_landmark(table, np.ones(len(table), np.int64), skip)
    n_rejected = by_landmark(table, table.rejected.astype(np.int64), skip)
    values: gtsam.Values | None = None
    moved = []
    for j, out_j in n_rejected.items():
        n_out = int(out_j.sum())
        if n_out < RESEAT_MIN_REJECTED:
            continue
        name = settings.landmarks[j]
        own = table.select(table.landmark == j)
        poses = [graph.values.atPose2(g.pose_key(b.movement, b.end)) for b in own]
        origins = np.array([(p.x(), p.y()) for p in poses], np.float64)
        if n_out <= n_rows[j].size - n_out:
            others = [graph.values.atPose2(g.pose_key(b.movement, 1 - b.end)) for b in own]
            starts = np.array([(p.x(), p.y()) for p in others], np.float64)
            point = np.asarray(graph.values.atPoint2(graph.key(name)), np.float64)
            if not out_of_reach(point, origins, starts, r_max):
                continue
        headings = np.array([p.theta() for p in poses], np.float64)
        bearings = np.array([b.bearing_rad for b in own], np.float64)
        fix = intersect_rays(origins, headings + bearings, REJECT_EPS * eps)
        if fix is None or fix.parallax_rad < MIN_RAY_PARALLAX_EPS * eps:
            continue
        pts = np.repeat(fix.point_fl[None, :], len(own), axis=0)
        r = wrap_rad(bearings - predicted_bearings(origins, headings, pts))
        if int((np.abs(r) <= REJECT_EPS * eps).sum()) <= len(own) - n_out:
            continue
        if values is None:
            values = gtsam.Values(graph.values)
        values.update(graph.key(name), fix.point_fl)
        state.rejected.difference_update(own)
        table.set_rejected(own, False)
        moved.append(name)
    if values is not None:
        graph.rebuild(state, values)
    return moved


def stuck(state: MapState, graph: MapGraph) -> str:
    """Why the map looks stuck away from its optimum, from its own record (empty if it does
    not): a reference landmark with at least :data:`STUCK_MIN_REFERENCE_BEARINGS` bearings in
    the map, more than half of them rejected (the gauge holds it where its bearings say it is
    not), or, with the distance prior, movement lengths that disagree with their driven
    distances (:func:`unit_misfit`)."""
    table, settings = graph.table, graph.settings
    for name, j in zip(settings.reference, settings.reference_indices(), strict=True):
        own = table.landmark == j
        n, n_out = int(own.sum()), int((own & table.rejected).sum())
        if n >= STUCK_MIN_REFERENCE_BEARINGS and 2 * n_out > n:
            return f"{n_out} of {n} bearings of the reference landmark {name} rejected"
    misfit_log = unit_misfit(state, graph)
    rel = settings.distance_prior_rel
    if rel is not None and misfit_log > STUCK_DISTANCE_SIGMAS * rel:
        return (
            f"movement lengths disagree with the driven distances by {misfit_log:.2f} in log "
            f"(median; the prior's std is {rel:g})"
        )
    return ""


def unit_misfit(state: MapState, graph: MapGraph) -> float:
    """Median absolute difference, in log length, between the placed movements' lengths in
    the map (FL) and their driven distances times the map's scale (FL per metre), over the
    movements with a distance (0 with fewer than :data:`STUCK_MIN_DISTANCES` of them, or
    without the distance prior)."""
    if not graph.has(g.SCALE_KEY):
        return 0.0
    values = graph.values
    log_scale = float(values.atVector(g.SCALE_KEY)[0])
    off = []
    for k, m in state.placed.items():
        d = graph.distance_m(m)
        if d is not None:
            o1, o2 = values.atPose2(g.pose_key(k, 0)), values.atPose2(g.pose_key(k, 1))
            length_fl = math.hypot(o2.x() - o1.x(), o2.y() - o1.y())
            off.append(abs(math.log(length_fl) - log_scale - math.log(d)))
    if len(off) < STUCK_MIN_DISTANCES:
        return 0.0
    return statistics.median(off)  # a few dozen numbers: faster than numpy's


#: A landmark this close (FL) to a keyframe of the map stands where the robot stood: the map
#: has collapsed onto a point where bearings are undefined (and its covariances mean nothing).
#: The robot's body keeps it several centimetres from any landmark, over 1% of any |L1 L2|
#: of a few metres.
COLLAPSE_FL = 0.005


def collapsed(state: MapState, graph: MapGraph) -> bool:
    """Whether a landmark of the map lies within :data:`COLLAPSE_FL` of one of its keyframes."""
    poses = [graph.values.atPose2(g.pose_key(k, end)) for k in state.placed for end in (0, 1)]
    if not poses or not state.in_graph:
        return False
    keyframes = np.array([[p.x(), p.y()] for p in poses])
    points = np.array([graph.point(name) for name in state.in_graph])
    gaps = np.hypot(*(points[:, None, :] - keyframes[None, :, :]).transpose(2, 0, 1))
    return bool(gaps.min() < COLLAPSE_FL)


def record_error(state: MapState, graph: MapGraph) -> float:
    """The graph's error at the map as it is with every bearing of the placed movements in it,
    the rejected ones too (each through the bearing factors' Huber loss): how well the map
    explains its whole record, comparable between two maps of the same state."""
    every = state.copy()
    every.rejected = set()
    scratch = MapGraph(graph.settings)  # full_graph records factor positions: not in ``graph``
    values = graph.values
    return float(scratch.full_graph(every, values).error(values))


def jumped(state: MapState, graph: MapGraph, before: dict[str, LandmarkEstimate]) -> str:
    """Which landmark of the estimates ``before`` the last update moved by more than
    :data:`JUMP_FL` and :data:`JUMP_SIGMAS` of its spread, and how far (empty if none did)."""
    for name, prev in before.items():
        if name not in state.in_graph:
            continue
        step = float(np.hypot(*(graph.point(name) - prev.mean_fl)))
        if step <= JUMP_FL:
            continue
        spread = widest_std(prev.cov_fl)
        if step > JUMP_SIGMAS * spread:
            return f"{name} jumped {step:.3f} FL ({step / max(spread, 1e-12):.0f} sigma)"
    return ""


def misfit(state: MapState, graph: MapGraph, rms_limit_rad: float) -> str:
    """Why the residuals are out of bounds: too many beyond :data:`REJECT_EPS` eps, or a
    robust RMS over ``rms_limit_rad`` (empty if they are not)."""
    settings = graph.settings
    bound = REJECT_EPS * settings.eps_rad
    frozen = state.frozen_bearings
    far = int((~graph.table.rejected & (np.abs(graph.residuals()) > bound)).sum())
    far += int((~frozen.rejected & (np.abs(frozen.residual_rad) > bound)).sum())
    r = graph.all_residuals(state)
    if far > max(1, MAX_REJECT_FRACTION * r.size):
        return f"{far} of {r.size} bearings more than {REJECT_EPS:g} eps from the map"
    robust = robust_rms(r)
    if robust > rms_limit_rad:
        limit = math.degrees(rms_limit_rad)
        return f"robust residual RMS {math.degrees(robust):.2f} deg > {limit:.2f}"
    return ""


def divergence(state: MapState, graph: MapGraph, before: dict[str, LandmarkEstimate]) -> str:
    """Why the map looks diverged after an update from the estimates ``before`` (empty if it
    does not): :func:`misfit` at the settings' divergence RMS, or :func:`jumped`."""
    return misfit(state, graph, graph.settings.divergence_rms_rad) or jumped(state, graph, before)


@dataclass(frozen=True)
class Snapshot:
    """The map before a movement: its state (a copy) and iSAM2's values then (never changed
    in place)."""

    state: MapState
    values: gtsam.Values


def snapshot(state: MapState, graph: MapGraph) -> Snapshot:
    """The map as it is now, for :func:`roll_back`."""
    return Snapshot(state.copy(), graph.values)


def roll_back(snap: Snapshot, graph: MapGraph) -> MapState:
    """The map as it was at ``snap``: its state (returned, to be used from now on) and its
    graph rebuilt from the values then (empty without a placed movement)."""
    graph.restore(snap.state, snap.values)
    return snap.state
