"""Once the log is processed: every keyframe's detections associated again with the final map,
and the names repaired where the detections it leaves unexplained meet.

Association movement by movement (:mod:`pipeline.association.assign`,
:mod:`pipeline.association.lifecycle`) names a detection with the map as it was then:
detections of a landmark from before its naming stay unnamed (unless it was named from them),
and a young map predicts bearings too loosely to split landmarks a few degrees apart. After the
last movement, the final map (each named landmark's point and covariance) and the final
placement of every keyframe (its pose and the pose's covariance) predict each bearing far more
sharply, and :func:`associate_final` assigns every keyframe's detections again, all of a
keyframe's at once (:func:`pipeline.association.jcbb.assign_jointly`: the largest jointly
compatible assignment, pairs unique by a margin, :data:`FINAL_MARGIN_CHI2`, the nearest of
landmarks in line takes their blob). Prediction variance: the point's covariance, the keyframe
pose's (its heading error common to every prediction of the keyframe), and the map's
estimated bearing noise; the bearings it names are not given to the estimator. A lone blob
where named landmarks line up (none clearly in front) is said to be theirs ("in line").
:func:`missing_reports` says when a class still has detections no name explains (every name
of it given or not), and where their rays meet (:func:`meeting_point`).

:func:`repair_final` then gives a free name, or the one the final map supports least, to the
point where those detections meet as the search names a landmark, or gives names under
suspicion anew where their detections and the unexplained ones meet (:func:`_rebuild`), or
moves the least supported name to that point when the final association explains more of the
class's detections with it there (:func:`_move_least_supported`).
:func:`weak_names` flags by name what the final map supports weakly: names given few of their
predicted detections, whose detections do not meet at one point, or that a missing landmark's
point lines up with from most keyframes (:func:`lined_up`).
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from enum import StrEnum, unique

import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad
from pipeline.association.assign import MovementAssignment
from pipeline.association.hypotheses import (
    FIT_TOL_EPS,
    MIN_PARALLAX_EPS,
    Hypothesis,
    Ray,
    RaySet,
    fit,
    ray_fits,
)
from pipeline.association.jcbb import assign_jointly, own_to_fl
from pipeline.association.lifecycle import (
    DISCOVER_FAN_KEYFRAMES,
    DISCOVER_FAN_SEEN_SHARE,
    DISCOVER_KEYFRAMES,
    DISCOVER_LINES,
    DISCOVER_MOVEMENTS,
    Lifecycle,
    seen_in_gate,
)
from pipeline.association.predict import (
    GATE_CHI2,
    MAX_PRED_STD_EPS,
    BearingModel,
    predict_bearings,
    predict_ranges,
)
from pipeline.association.result import MovementAssociation
from pipeline.association.support import misfit
from pipeline.estimate import LandmarkEstimate
from pipeline.geometry import KeyframePose

#: A pairing is kept when every jointly compatible assignment of its keyframe as large without
#: it has a joint squared Mahalanobis distance this much larger (chi-square units: the best
#: assignment at least e^1.75, about 6, times as likely as any other;
#: :func:`pipeline.association.jcbb.jcbb`). Looser than the 9 of association movement by
#: movement (:data:`pipeline.association.jcbb.MARGIN_CHI2`), where a wrong pairing goes into
#: the map and the hypotheses; here it only labels a detection. Measured on the random arenas of
#: ``tests/pipeline/test_association_final.py`` (heading std as stated; four times looser):
#: 3 names 92.7 / 92.2 % of the detections, 99.5 / 99.35 % of them right; 3.5 names 92.5 /
#: 91.9 %, 99.6 / 99.6 % right; 5 names 90.6 / 89.5 %, 99.8 / 99.85 % right.
FINAL_MARGIN_CHI2 = 3.5

#: With every name of a class given, this many of its detections that no named landmark
#: explains with the final map are reported: a landmark of the class may be missing from the map
#: and one of the names may stand where rays of several landmarks meet.
MISSING_UNEXPLAINED = 3
#: ... and where their rays meet is said when rays of this many keyframes pass within eps of it.
MISSING_KEYFRAMES = 4
#: Where rays meet is sought among at most this many of their crossings (every k-th of them):
#: a landmark seen from m keyframes has about m^2 / 2 crossings near it, and testing every
#: crossing against every ray grows as the cube of the rays (800 ms per run with 330 rays
#: unexplained, 32 landmarks of which 17-19 named).
MEETING_CROSSINGS = 5000
#: Once the log is processed, the names of a class under suspicion (its doubtful ones; then the
#: one, then the REBUILD_SUSPECTS, the final map does not hold or, after those, gives a
#: detection at the smallest share of their predictions) are given anew where their detections
#: and those the final map left unexplained meet, when those points explain REBUILD_GAIN
#: detections more than the names do; and the least supported name moves to where the
#: unexplained ones meet when the final map explains REBUILD_GAIN more of the class's detections
#: with it there.
REBUILD_SUSPECTS = 2
REBUILD_GAIN = 8
#: Once the log is processed, a point the unexplained detections meet at is a named landmark
#: seen again only when also this close to it (squared Mahalanobis distance with both
#: covariances; chi-square, 2 dof, 99.9 %): from many keyframes a landmark lines up with a named
#: one a few degrees away, whose gate then holds most of its rays, though the final map told them
#: apart.
FINAL_APART_CHI2 = 13.82


@unique
class Status(StrEnum):
    """What became of one detection with the final map (the summary's keys)."""

    #: given a name
    NAMED = "named"
    #: one blob where several named landmarks line up (predicted within eps of each other, none
    #: clearly in front, no other blob near: it is one or several of them)
    IN_LINE = "in line"
    #: contested by several named landmarks
    CONTESTED = "contested"
    #: explained by none
    UNEXPLAINED = "unexplained"
    #: at a keyframe the map does not hold
    NOT_PLACED = "not placed"


STATUSES: tuple[Status, ...] = tuple(Status)


@dataclass(frozen=True)
class FinalDetection:
    """One keyframe detection of a shared class, as the final map associates it.

    Attributes
    ----------
    movement, end : int
        Its keyframe: movement index, 0 at O1 and 1 at O2.
    label : str
        The class (colour or band code).
    bearing_rad : float
        The detection's bearing, rad, relative to the keyframe's heading.
    name : str or None
        The landmark it is (``red#2``), None when not named.
    status : str
        One of :data:`STATUSES`.
    in_line : tuple of str
        With status ``in line``, the landmarks that line up on its blob (else empty).
    """

    movement: int
    end: int
    label: str
    bearing_rad: float
    name: str | None
    status: Status
    in_line: tuple[str, ...] = ()


def associate_final(
    detections: Mapping[tuple[int, int], Mapping[str, Sequence[float]]],
    poses: Mapping[tuple[int, int], KeyframePose],
    known: Mapping[str, Sequence[tuple[str, LandmarkEstimate]]],
    *,
    noise_rad: float,
    eps_rad: float,
) -> list[FinalDetection]:
    """Associate every keyframe's detections with the final map.

    Parameters
    ----------
    detections : dict (movement, end) -> dict label -> bearings (rad)
        Each keyframe's detections per shared class.
    poses : dict (movement, end) -> KeyframePose
        The keyframes the map holds, as it places them now (FL).
    known : dict label -> list of (name, LandmarkEstimate)
        The named landmarks of each class in the final map (FL).
    noise_rad : float
        Bearing noise std (the map's estimate), rad.
    eps_rad : float
        Bearing error bound eps: landmarks predicted within it of each other are in line.

    Returns
    -------
    list of FinalDetection
        Every detection, in keyframe order, then class, then detection order.
    """
    out: list[FinalDetection] = []
    for key in sorted(detections):
        movement, end = key
        pose = poses.get(key)
        for label, bearings in detections[key].items():
            det = np.asarray(bearings, np.float64).reshape(-1)
            names = [name for name, _ in known.get(label, ())]
            status: list[Status] = [
                Status.NOT_PLACED if pose is None else Status.UNEXPLAINED
            ] * det.size
            given: list[str | None] = [None] * det.size
            lined: list[tuple[str, ...]] = [()] * det.size
            if pose is not None and names and det.size:
                pairs, contested, in_line = _assign(pose, det, known[label], noise_rad, eps_rad)
                for i, j in pairs:
                    given[j], status[j] = names[i], Status.NAMED
                for j in contested:
                    status[j] = Status.CONTESTED
                for j, lms in in_line.items():
                    status[j], lined[j] = Status.IN_LINE, tuple(names[i] for i in lms)
            out.extend(
                FinalDetection(movement, end, label, float(b), n, s, o)
                for b, n, s, o in zip(det, given, status, lined, strict=True)
            )
    return out


def _assign(
    pose: KeyframePose,
    det_rad: NDArray[np.float64],
    known: Sequence[tuple[str, LandmarkEstimate]],
    noise_rad: float,
    eps_rad: float,
) -> tuple[list[tuple[int, int]], list[int], dict[int, list[int]]]:
    """At one keyframe: pairs (index in ``known``, detection), contested detections, and
    detections that are one blob where landmarks line up (detection -> indices in ``known``:
    contested by them, they unpaired, predicted within eps of each other, no other detection
    within eps)."""
    pts = np.array([e.mean_fl for _, e in known]).reshape(-1, 2)
    covs = np.array([e.cov_fl for _, e in known]).reshape(-1, 2, 2)
    pred, std = predict_bearings(
        pose.origin_fl,
        pose.heading_rad,
        pts,
        covs,
        bearing_var_rad=noise_rad**2,
        pose_cov=pose.cov,
    )
    sharp_mask = std <= MAX_PRED_STD_EPS * eps_rad
    sharp = np.flatnonzero(sharp_mask)
    origin_var = float(np.trace(pose.cov[:2, :2])) / 2.0
    range_fl, range_std_fl = predict_ranges(pose.origin_fl, pts, covs, origin_var_fl=origin_var)
    # the keyframe's detections assigned jointly (its heading error is common to them all)
    (a,) = assign_jointly(
        pts,
        covs,
        sharp_mask[None, :],
        pose.origin_fl[None, :],
        np.array([pose.heading_rad]),
        own_to_fl(pose.cov, pose.heading_rad),
        [det_rad],
        noise_rad**2,
        margin=FINAL_MARGIN_CHI2,
        range_fl=range_fl[None, :],
        range_std_fl=range_std_fl[None, :],
        in_line_rad=eps_rad,
    )
    free = np.setdiff1d(sharp, [i for i, _ in a.pairs])
    in_line: dict[int, list[int]] = {}
    for j in a.contested_detections:
        off = wrap_rad(det_rad[j] - pred[free])
        gated = free[off**2 <= GATE_CHI2 * std[free] ** 2]
        lone = int((np.abs(wrap_rad(det_rad - det_rad[j])) <= eps_rad).sum()) == 1
        p = pred[gated]
        together = bool(np.all(np.abs(wrap_rad(p[:, None] - p[None, :])) <= eps_rad))
        if gated.size >= 2 and lone and together:
            in_line[j] = [int(i) for i in gated]
    contested = [j for j in a.contested_detections if j not in in_line]
    return a.pairs, sorted(contested), in_line


def missing_reports(
    detections: Sequence[FinalDetection],
    given: Mapping[str, tuple[int, int]],
    poses: Mapping[tuple[int, int], KeyframePose],
    eps_rad: float,
) -> dict[str, str]:
    """Per class of ``given`` (label -> names given, names in the catalog) with at least
    :data:`MISSING_UNEXPLAINED` detections left unexplained by the final map, whether or not
    every name of it is given: what to say, with where their rays meet (:func:`meeting_point`,
    keyframes from ``poses``) when rays of :data:`MISSING_KEYFRAMES` keyframes or more do.

    Returns
    -------
    dict label -> str
        The report for each such class.
    """
    out = {}
    for label, (named, capacity) in given.items():
        left = [d for d in detections if d.label == label and d.status == Status.UNEXPLAINED]
        if len(left) < MISSING_UNEXPLAINED:
            continue
        keyframes = len({(d.movement, d.end) for d in left})
        total = sum(1 for d in detections if d.label == label)
        text = (
            f"{len(left)} of {total} detection(s) of {label} at {keyframes} keyframe(s) "
            "explained by no named landmark with the final map"
        )
        if named >= capacity:
            text += (
                f", though every name of {label} is given: a landmark may be missing from the "
                "map, and a name may stand where rays of several landmarks meet"
            )
        else:
            text += (
                f", {named} of {capacity} names of {label} given: landmark(s) of {label} are "
                "missing from the map"
            )
        if (met := missing_point(detections, label, poses, eps_rad)) is not None:
            (x, y), n = met
            text += f" (rays of {n} keyframes meet near ({x:.2f}, {y:.2f}) FL)"
        out[label] = text
    return out


def missing_point(
    detections: Sequence[FinalDetection],
    label: str,
    poses: Mapping[tuple[int, int], KeyframePose],
    eps_rad: float,
) -> tuple[NDArray[np.float64], int] | None:
    """Where the detections of ``label`` the final map left unexplained meet
    (:func:`meeting_point`), when at least :data:`MISSING_UNEXPLAINED` are and rays of
    :data:`MISSING_KEYFRAMES` keyframes or more of ``poses`` meet: the point (FL, (2,)) and the
    number of keyframes; else None."""
    left = sum(1 for d in detections if d.label == label and d.status == Status.UNEXPLAINED)
    if left < MISSING_UNEXPLAINED:
        return None
    met = meeting_point(unexplained_rays(detections, label, poses), eps_rad)
    if met is None or len(met[1]) < MISSING_KEYFRAMES:
        return None
    return met[0], len(met[1])


#: A name the final association gives a detection at fewer than this share of the keyframes
#: where the final map predicts it sharply enough to gate is weak (flagged by name): its point
#: may stand where rays of several landmarks meet. Measured on 24 simulated runs of 12 and 16
#: identical landmarks: 16 of 21 names more than 10 cm off are below it, 24 of 214 within
#: 10 cm.
WEAK_SHARE = 0.75
#: Where the detections of a class that the final map leaves unexplained meet
#: (:func:`missing_point`: a landmark missing from the map), a name whose gate holds that
#: point's bearing at this share or more of the keyframes where the final map predicts it
#: sharply is weak: the two cannot be told apart from most keyframes, so its detections may be
#: the missing landmark's and its point pulled between them. Measured on 180 simulated runs of
#: 8, 12 and 16 identical landmarks: the two names more than 10 cm off that nothing else
#: flagged line up with their missing landmark's point at 86 and 93 %; at half, 7 names within
#: 10 cm are flagged besides them.
LINED_UP_SHARE = 0.5


def given_share(
    name: str,
    estimate: LandmarkEstimate,
    detections: Sequence[FinalDetection],
    poses: Mapping[tuple[int, int], KeyframePose],
    *,
    noise_rad: float,
    eps_rad: float,
) -> tuple[int, int]:
    """At how many keyframes of ``poses`` the final map predicts ``name`` (its ``estimate``,
    FL) sharply enough to gate (:func:`sharp_predictions`), and how many of ``detections``
    were given ``name``: (given, predicted)."""
    predicted = len(sharp_predictions(estimate, poses, noise_rad=noise_rad, eps_rad=eps_rad))
    return sum(d.name == name for d in detections), predicted


def sharp_predictions(
    estimate: LandmarkEstimate,
    poses: Mapping[tuple[int, int], KeyframePose],
    *,
    noise_rad: float,
    eps_rad: float,
) -> list[tuple[KeyframePose, float, float]]:
    """The keyframes of ``poses`` where the final map predicts a landmark (its ``estimate``,
    FL) sharply enough to gate (std at most :data:`MAX_PRED_STD_EPS` eps, bearing noise
    ``noise_rad``, the pose's covariance): each with the predicted bearing and its std (rad,
    robot frame)."""
    out = []
    for p in poses.values():
        pred, std = predict_bearings(
            p.origin_fl,
            p.heading_rad,
            estimate.mean_fl[None, :],
            estimate.cov_fl[None, :, :],
            bearing_var_rad=noise_rad**2,
            pose_cov=p.cov,
        )
        if std[0] <= MAX_PRED_STD_EPS * eps_rad:
            out.append((p, float(pred[0]), float(std[0])))
    return out


def weak_names(
    detections: Sequence[FinalDetection],
    poses: Mapping[tuple[int, int], KeyframePose],
    mapped: Mapping[str, LandmarkEstimate],
    names: Collection[str],
    *,
    noise_rad: float,
    eps_rad: float,
) -> dict[str, str]:
    """The ``names`` (in the final map ``mapped``) the final association gives a detection at
    fewer than :data:`WEAK_SHARE` of the keyframes where the map predicts them
    (:func:`given_share`), whose detections there do not meet at one point
    (:func:`pipeline.association.support.misfit`, the ``names`` tested together), or that a
    landmark missing from the map (:func:`missing_point`) lines up with at
    :data:`LINED_UP_SHARE` of those keyframes or more (:func:`lined_up`), with why."""
    out = {}
    missing = {
        label: met[0]
        for label in sorted({d.label for d in detections})
        if (met := missing_point(detections, label, poses, eps_rad)) is not None
    }
    for name in sorted(names):
        e = mapped.get(name)
        if e is None:
            continue
        given, predicted = given_share(
            name, e, detections, poses, noise_rad=noise_rad, eps_rad=eps_rad
        )
        point = missing.get(name.rpartition("#")[0])
        if predicted and given < WEAK_SHARE * predicted:
            out[name] = (
                f"given a detection at {given} of {predicted} keyframes where the final map "
                f"predicts it ({100 * given / predicted:.0f} %): it may stand where rays of "
                "several landmarks meet"
            )
        elif (why := _misfit(name, e, detections, poses, noise_rad, len(names))) is not None:
            out[name] = why
        elif point is not None:
            lined, sharp = lined_up(e, point, poses, noise_rad=noise_rad, eps_rad=eps_rad)
            if sharp and lined >= LINED_UP_SHARE * sharp:
                x, y = point
                out[name] = (
                    f"the landmark missing near ({x:.2f}, {y:.2f}) FL, where detections the "
                    f"final map left unexplained meet, lies in its gate at {lined} of {sharp} "
                    "keyframes where the final map predicts it: its detections may be that "
                    "landmark's"
                )
    return out


def lined_up(
    estimate: LandmarkEstimate,
    point_fl: NDArray[np.float64],
    poses: Mapping[tuple[int, int], KeyframePose],
    *,
    noise_rad: float,
    eps_rad: float,
) -> tuple[int, int]:
    """At how many keyframes of ``poses`` the final map predicts a landmark (its
    ``estimate``, FL) sharply enough to gate (:func:`sharp_predictions`), and at how many of those
    the bearing of ``point_fl`` (FL, (2,)) lies in its gate (chi-square 1 dof, 99.9 %):
    (lined up, predicted)."""
    sharp = sharp_predictions(estimate, poses, noise_rad=noise_rad, eps_rad=eps_rad)
    lined = 0
    for p, pred, std in sharp:
        d = point_fl - p.origin_fl
        off = float(wrap_rad(math.atan2(d[1], d[0]) - p.heading_rad - pred))
        lined += off**2 <= GATE_CHI2 * std**2
    return lined, len(sharp)


def _misfit(
    name: str,
    estimate: LandmarkEstimate,
    detections: Sequence[FinalDetection],
    poses: Mapping[tuple[int, int], KeyframePose],
    noise_rad: float,
    names: int,
) -> str | None:
    """:func:`pipeline.association.support.misfit` of the detections given ``name``, each
    ray's variance the bearing noise's and its keyframe pose's at the map's point."""
    rays = [
        (p, d.bearing_rad)
        for d in detections
        if d.name == name and d.status == Status.NAMED
        if (p := poses.get((d.movement, d.end))) is not None
    ]
    if not rays:
        return None
    var = [
        float(
            predict_bearings(
                p.origin_fl,
                p.heading_rad,
                estimate.mean_fl[None, :],
                np.zeros((1, 2, 2)),
                bearing_var_rad=noise_rad**2,
                pose_cov=p.cov,
            )[1][0]
        )
        ** 2
        for p, _ in rays
    ]
    return misfit(
        np.array([p.origin_fl for p, _ in rays], np.float64).reshape(-1, 2),
        np.array([p.heading_rad + b for p, b in rays], np.float64),
        np.array(var, np.float64),
        estimate.mean_fl,
        names,
    )


def unexplained_rays(
    detections: Sequence[FinalDetection],
    label: str,
    poses: Mapping[tuple[int, int], KeyframePose],
    names: Collection[str] = (),
) -> list[Ray]:
    """The rays (FL) of the detections of ``label`` the final map left unexplained, and of
    those it gave one of ``names``, at the keyframes ``poses`` holds (``detection``: the index
    among those detections)."""
    left = [
        d
        for d in detections
        if d.label == label
        and (d.status == Status.UNEXPLAINED or (d.name is not None and d.name in names))
    ]
    return [
        Ray.placed(d.movement, d.end, k, d.bearing_rad, p.origin_fl, p.heading_rad)
        for k, d in enumerate(left)
        if (p := poses.get((d.movement, d.end))) is not None
    ]


def meeting_point(
    rays: Sequence[Ray], eps_rad: float
) -> tuple[NDArray[np.float64], list[Ray]] | None:
    """Where the most keyframes' rays pass within eps of one point.

    Parameters
    ----------
    rays : list of Ray
        Rays in FL.
    eps_rad : float
        Bearing error bound: a ray passes near a point when within it; two rays cross usefully
        with at least :data:`pipeline.association.hypotheses.MIN_PARALLAX_EPS` eps between
        them.

    Returns
    -------
    (point_fl (2,), rays) or None
        The crossing of two rays of different keyframes (ahead of both; of more than
        :data:`MEETING_CROSSINGS` crossings, every k-th) that the most keyframes have a ray
        within eps of, moved to the least-squares point of those rays (one per
        keyframe, the nearest), and the rays within eps of that point (one per keyframe, the
        nearest); None when no two rays cross.
    """
    if len(rays) < 2:
        return None
    rs = RaySet(rays)
    tol = FIT_TOL_EPS * eps_rad
    a, b = np.triu_indices(len(rays), 1)
    keep = (rs.frames[a] != rs.frames[b]) & (
        np.abs(wrap_rad(rs.dirs_rad[a] - rs.dirs_rad[b])) >= MIN_PARALLAX_EPS * eps_rad
    )
    a, b = a[keep], b[keep]
    ua, ub = rs.units[a], rs.units[b]
    cross = ua[:, 0] * ub[:, 1] - ua[:, 1] * ub[:, 0]
    d = rs.origins_fl[b] - rs.origins_fl[a]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # parallel: no crossing
        t1 = (d[:, 0] * ub[:, 1] - d[:, 1] * ub[:, 0]) / cross
        t2 = (d[:, 0] * ua[:, 1] - d[:, 1] * ua[:, 0]) / cross
    ahead = (t1 > 0.0) & (t2 > 0.0)
    if not ahead.any():
        return None
    points = rs.origins_fl[a[ahead]] + t1[ahead, None] * ua[ahead]
    points = points[:: -(-len(points) // MEETING_CROSSINGS)]  # every k-th, at most that many
    point = points[int(np.argmax(rs.keyframes_within(rs.errors(points), tol)))]
    near = rs.nearest_per_keyframe(rs.errors(point[None, :])[0], tol)
    # least squares: the point nearest (perpendicular distance) to the rays it gathered
    direction = np.array([r.direction_rad for r in near])
    normal = np.column_stack((-np.sin(direction), np.cos(direction)))
    lhs = normal.T @ normal
    if abs(float(np.linalg.det(lhs))) > 1e-12:
        origin = np.array([r.origin_fl for r in near], np.float64).reshape(-1, 2)
        point = np.linalg.solve(lhs, normal.T @ (normal * origin).sum(axis=1))
    return point, rs.nearest_per_keyframe(rs.errors(point[None, :])[0], tol)


def repair_final(
    names: Lifecycle,
    final: Sequence[FinalDetection],
    poses: Mapping[tuple[int, int], KeyframePose],
    mapped: Mapping[str, LandmarkEstimate],
    index: int,
    noise_rad: float,
) -> MovementAssociation | None:
    """Once the log is processed, per class, where the detections the final map leaves
    unexplained meet at one point as a search names a landmark (:func:`_final_point`): with
    names of the class still free, the point gets the next one (and the rest of the rays are
    searched again while names are free: ``named_at_end``); with every name given, the name the
    final map supports least (:func:`_least_supported`: one it does not hold, else the one the
    final association gave a detection at the smallest share of the keyframes where the final
    map predicts it; doubtful or not) is retracted and given to the point, when the point
    explains more detections than the name does (the likelier of the two). When neither gives
    a name, names under suspicion may be given anew (:func:`_rebuild`); failing that too, the
    least supported name moves to the point when the final association explains
    :data:`REBUILD_GAIN` more of the class's detections with it there
    (:func:`_move_least_supported`: the blobs it takes from other names or leaves in line
    count, not only the point's own rays).

    ``names`` holds the names given and gives the new ones, ``final`` is
    :func:`associate_final`'s association, ``poses`` and ``mapped`` the final map, ``index``
    the last movement, ``noise_rad`` the bearing noise std ``final`` was made with. Returns
    what changed (``retracted``, ``named_at_end``, ``confirmed``, ``history``: the estimator
    forgets the retracted landmarks, takes the history and settles), or None when nothing
    did."""
    # after the last movement: no ray is its own
    out = MovementAssociation(index + 1, assignment=MovementAssignment(index + 1, {}))
    for label, count in names.capacity.items():
        full = len(names.named[label]) >= count
        given = len(out.confirmed)
        rays = unexplained_rays(final, label, poses)
        point: tuple[Hypothesis, int] | None = None  # with every name given
        while (found := _final_point(names, label, rays, mapped, final, poses)) is not None:
            h, lines = found
            out.names.setdefault(label, ([], []))
            if full:
                share, ranked = _least_supported(names, label, final, poses, mapped)
                weakest = ranked[0]
                # the name moves only to a point that explains more detections than it does
                given_to = sum(d.name == weakest for d in final)
                if len(h.rays) > given_to:
                    x, y = h.point_fl
                    why = (
                        f"{_support_text(weakest, share, mapped)}, the least of {label}; "
                        f"retracted once the log was processed: the name goes to "
                        f"({x:.2f}, {y:.2f}) FL, where {len(h.rays)} detections the final map "
                        f"left unexplained meet (it was given {given_to})"
                    )
                    names.give_name(label, h, lines, out, searched=True, retract=weakest, why=why)
                else:
                    point = found
                break
            names.give_name(label, h, lines, out, searched=True)
            x, y = h.point_fl
            out.named_at_end[out.confirmed[-1]] = (
                f"named once the log was processed: {len(h.rays)} detections the final map "
                f"left unexplained, from {len({(r.movement, r.end) for r in h.rays})} "
                f"keyframes along {lines} lines of sight, meet at ({x:.2f}, {y:.2f}) FL"
            )
            full = len(names.named[label]) >= count
            if full:
                break
            rays = [r for r in rays if (r.movement, r.end, r.detection) not in h.keys]
        if len(out.confirmed) == given:
            _rebuild(names, label, final, poses, mapped, out)
        if len(out.confirmed) == given and point is not None:
            _move_least_supported(names, label, final, poses, mapped, point, noise_rad, out)
    return out if out.confirmed else None


def _move_least_supported(
    names: Lifecycle,
    label: str,
    final: Sequence[FinalDetection],
    poses: Mapping[tuple[int, int], KeyframePose],
    mapped: Mapping[str, LandmarkEstimate],
    point: tuple[Hypothesis, int],
    noise_rad: float,
    out: MovementAssociation,
) -> None:
    """With every name of ``label`` given: the name the final map supports least
    (:func:`_least_supported`) goes to ``point`` (where the unexplained detections meet, and
    its lines of sight) when the final map explains :data:`REBUILD_GAIN` more of the class's
    detections with it there (:func:`explained_if_moved`)."""
    h, lines = point
    share, ranked = _least_supported(names, label, final, poses, mapped)
    weakest = ranked[0]
    before, after = explained_if_moved(final, label, poses, mapped, names, weakest, h, noise_rad)
    if after < before + REBUILD_GAIN:
        return
    x, y = h.point_fl
    doubt = names.support[weakest].doubt()
    why = (
        f"{f'{doubt}; ' if doubt else ''}"
        f"{_support_text(weakest, share, mapped)}, the least of {label}; "
        f"retracted once the log was processed: the name goes to ({x:.2f}, {y:.2f}) FL, where "
        f"{len(h.rays)} detections the final map left unexplained meet; with it there the "
        f"final map explains {after} detections of {label}, against {before}"
    )
    names.give_name(label, h, lines, out, searched=True, retract=weakest, why=why)


def explained_if_moved(
    final: Sequence[FinalDetection],
    label: str,
    poses: Mapping[tuple[int, int], KeyframePose],
    mapped: Mapping[str, LandmarkEstimate],
    names: Lifecycle,
    name: str,
    h: Hypothesis,
    noise_rad: float,
) -> tuple[int, int]:
    """How many detections of ``label`` the final association (``final``, with the final map
    ``poses`` and ``mapped`` under the names of ``names``) explains (named or in line) as it
    is, and with ``name`` moved to the point of ``h`` (its covariance too), the map otherwise
    as it is: (before, after)."""
    explained = (Status.NAMED, Status.IN_LINE)
    own = [d for d in final if d.label == label]
    detections: dict[tuple[int, int], dict[str, list[float]]] = {}
    for d in own:
        detections.setdefault((d.movement, d.end), {}).setdefault(label, []).append(d.bearing_rad)
    known = [
        (n, LandmarkEstimate(h.point_fl, h.cov_fl) if n == name else mapped[n])
        for n in names.named[label]
        if n == name or n in mapped
    ]
    moved = associate_final(
        detections, poses, {label: known}, noise_rad=noise_rad, eps_rad=names.model.eps_rad
    )
    return sum(d.status in explained for d in own), sum(d.status in explained for d in moved)


def _rebuild(
    names: Lifecycle,
    label: str,
    final: Sequence[FinalDetection],
    poses: Mapping[tuple[int, int], KeyframePose],
    mapped: Mapping[str, LandmarkEstimate],
    out: MovementAssociation,
) -> None:
    """Give names of ``label`` under suspicion anew (:data:`REBUILD_SUSPECTS`): where their
    detections and the ones the final map leaves unexplained meet (:func:`_final_point`, one
    point per name at most), when the points explain :data:`REBUILD_GAIN` detections more
    than the names do; each point gets the name nearest to it, unless within
    :data:`FINAL_APART_CHI2` of it already."""
    support = names.support
    share, weakest = _least_supported(names, label, final, poses, mapped)
    doubtful = [n for n in names.named[label] if support[n].doubt() is not None]
    suspects = [doubtful] if doubtful else []
    suspects += [weakest[:k] for k in range(1, REBUILD_SUSPECTS + 1)]
    for suspected in suspects:
        rays = unexplained_rays(final, label, poses, suspected)
        found: list[tuple[Hypothesis, int]] = []
        while (
            len(found) < len(suspected)
            and (f := _final_point(names, label, rays, mapped, final, poses, suspected)) is not None
        ):
            found.append(f)
            rays = [r for r in rays if (r.movement, r.end, r.detection) not in f[0].keys]
        before = sum(d.name in suspected for d in final)
        explained = sum(len(h.rays) for h, _ in found)
        if explained >= before + REBUILD_GAIN:
            break
    else:
        return
    pairs = sorted(
        (float(np.sum((h.point_fl - mapped[n].mean_fl) ** 2)) if n in mapped else np.inf, k, n)
        for k, (h, _) in enumerate(found)
        for n in suspected
    )
    given: dict[int, str] = {}
    for _, k, n in pairs:
        if k not in given and n not in given.values():
            given[k] = n
    given = {k: n for k, n in given.items() if not _stays(found[k][0], mapped.get(n))}
    out.names.setdefault(label, ([], []))
    for k, n in given.items():
        h, lines = found[k]
        x, y = h.point_fl
        seen = support[n].doubt() or _support_text(n, share, mapped)
        why = (
            f"{seen}; given anew once the log was processed: "
            f"with the detections the final map left unexplained, those of "
            f"{', '.join(suspected)} meet at {len(found)} point(s), which explain "
            f"{explained} detections against {before}; this one "
            f"at ({x:.2f}, {y:.2f}) FL along {lines} lines of sight"
        )
        names.give_name(label, h, lines, out, searched=True, retract=n, why=why)


def _least_supported(
    names: Lifecycle,
    label: str,
    final: Sequence[FinalDetection],
    poses: Mapping[tuple[int, int], KeyframePose],
    mapped: Mapping[str, LandmarkEstimate],
) -> tuple[dict[str, float], list[str]]:
    """Each name of ``label`` with its share of predictions the final association gave a
    detection (:func:`_final_share`), and the names from the least supported: those the final
    map does not hold first (it gives them nothing), then by share."""
    share = {n: _final_share(n, final, poses, mapped, names.model) for n in names.named[label]}
    return share, sorted(share, key=lambda n: (n in mapped, share[n]))


def _support_text(name: str, share: Mapping[str, float], mapped: Collection[str]) -> str:
    """What the final map gives ``name``, in words."""
    if name not in mapped:
        return "not in the final map (its bearings never met at one point)"
    return f"given a detection at {100 * share[name]:.0f} % of the keyframes where predicted"


def _final_point(
    names: Lifecycle,
    label: str,
    rays: Sequence[Ray],
    mapped: Mapping[str, LandmarkEstimate],
    final: Sequence[FinalDetection],
    poses: Mapping[tuple[int, int], KeyframePose],
    apart_from: Collection[str] = (),
) -> tuple[Hypothesis, int] | None:
    """Where ``rays`` (unexplained by the final map) meet as the search names a landmark:
    :data:`~pipeline.association.lifecycle.DISCOVER_KEYFRAMES` keyframes,
    :data:`~pipeline.association.lifecycle.DISCOVER_LINES` lines of sight over
    :data:`~pipeline.association.lifecycle.DISCOVER_MOVEMENTS` movements, every ray within
    eps, not a named landmark seen again (mostly its rays and within :data:`FINAL_APART_CHI2`
    of it); or, for a landmark seen from a narrow fan, one line of sight fewer from
    :data:`~pipeline.association.lifecycle.DISCOVER_FAN_KEYFRAMES` keyframes, its class
    detected in the gate at :data:`~pipeline.association.lifecycle.DISCOVER_FAN_SEEN_SHARE`
    of the keyframes of ``poses`` (the final map's, associated as ``final``) where its point is
    predicted sharply. The fitted point and its lines of sight, or None."""
    eps, sigma = names.model.eps_rad, names.model.sigma_rad
    met = meeting_point(rays, eps)
    if met is None or len(met[1]) < DISCOVER_KEYFRAMES:
        return None
    h = fit(label, met[1], eps, sigma, met[0])
    if h is None:
        return None
    lines = h.lines_of_sight(names.distinct_rad)
    fan = lines == DISCOVER_LINES - 1 and len(h.rays) >= DISCOVER_FAN_KEYFRAMES
    if lines < DISCOVER_LINES and not fan:
        return None
    if len({r.movement for r in h.rays}) < DISCOVER_MOVEMENTS:
        return None
    for n, e in names.known(label, mapped):
        if n in apart_from:
            continue
        if _stays(h, e) and 2 * sum(ray_fits(r, e, sigma) for r in h.rays) > len(h.rays):
            return None  # mostly bearings of a named landmark: that one, left unexplained
    if fan:
        seen, predicted = _seen_at_end(h, final, poses, names.model)
        if seen < DISCOVER_FAN_SEEN_SHARE * predicted:
            return None
    return h, lines


def _seen_at_end(
    h: Hypothesis,
    final: Sequence[FinalDetection],
    poses: Mapping[tuple[int, int], KeyframePose],
    model: BearingModel,
) -> tuple[int, int]:
    """:func:`~pipeline.association.lifecycle.seen_in_gate` at the final map's keyframes from
    the first movement of ``h``'s rays on, each with every detection of ``h``'s class."""
    since = min(r.movement for r in h.rays)
    keys = sorted(k for k in poses if k[0] >= since)
    by_key: dict[tuple[int, int], list[float]] = {}
    for d in final:
        if d.label == h.label:
            by_key.setdefault((d.movement, d.end), []).append(d.bearing_rad)
    origins = np.array([poses[k].origin_fl for k in keys], np.float64).reshape(-1, 2)
    headings = np.array([poses[k].heading_rad for k in keys], np.float64)
    bearings = [np.array(by_key.get(k, ()), np.float64) for k in keys]
    return seen_in_gate(h, origins, headings, bearings, model)


def _stays(h: Hypothesis, e: LandmarkEstimate | None) -> bool:
    """Whether ``h`` is within :data:`FINAL_APART_CHI2` of ``e`` (False: no ``e``)."""
    if e is None:
        return False
    d = h.point_fl - e.mean_fl
    return float(d @ np.linalg.solve(h.cov_fl + e.cov_fl, d)) <= FINAL_APART_CHI2


def _final_share(
    name: str,
    final: Sequence[FinalDetection],
    poses: Mapping[tuple[int, int], KeyframePose],
    mapped: Mapping[str, LandmarkEstimate],
    model: BearingModel,
) -> float:
    """Share of the keyframes where the final map predicts ``name`` sharply enough to gate at
    which the final association gave it a detection (1 when not in the map)."""
    e = mapped.get(name)
    if e is None or not poses:
        return 1.0
    given, predicted = given_share(
        name, e, final, poses, noise_rad=model.sigma_rad, eps_rad=model.eps_rad
    )
    return given / max(predicted, 1)
