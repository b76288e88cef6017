"""A movement placed by matching its detections with the map, when too few are identified.

A movement is placed from bearings of identified landmarks (the reference pair, landmarks of a
class of their own, named landmarks of shared classes once association named them). When one
of its keyframes lies where a placed movement ended or starts (the robot turns in place) but
too few of its detections are identified to place it, :func:`match_movement` places it from
every detection: it tries the headings that turn a detection at that keyframe onto a
landmark of its class (those matching the most there), and for each every length that turns a
detection at the other keyframe onto one, counts the detections of both keyframes that fall
within eps of a landmark of their class, refines the best poses by least squares on the
detections they match (:func:`pipeline.geometry.resect`), and keeps the best when it
clearly beats every pose that tells another story (:data:`MATCH_LEAD`).
:func:`place_left_out` places, once the log is processed, the movements the map left out.

Association places each movement itself before the estimator does (:func:`place_movement`):
chained on the end of the previous movement when that one was placed
(:func:`pipeline.geometry.place_chained`; one bearing at each keyframe suffices), else by
resection (:func:`pipeline.geometry.resect`, four bearings at
least); the associator falls back on :func:`match_movement` after a placed movement.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad
from pipeline.association.result import deg_text
from pipeline.estimate import LandmarkEstimate
from pipeline.geometry import (
    KeyframePose,
    MovementPose,
    Resection,
    Sightings,
    determinacy,
    keyframe_poses_of,
    place_chained,
    pose_params,
    resect,
)
from pipeline.joint.noise import robust_std

#: A detection matches a landmark of its class predicted within this many eps.
MATCH_TOL_EPS = 1.0
#: A pose is kept when this many detections match at its two keyframes ...
MATCH_MIN = 6
#: ... at least this many at each ...
MATCH_MIN_PER_END = 2
#: ... and this many more than at any refined pose that tells another story: one that matches
#: MATCH_STORY detections or more (that it matches too) with other landmarks, and lies outside
#: its 3-std bounds (heading more than MATCH_TOL_EPS eps away, O1 or the length more than 3
#: std away for a bearing noise of half that).
MATCH_LEAD = 2
MATCH_STORY = 2
#: Headings tried (those that match the most detections at the known keyframe).
MATCH_HEADINGS = 12
#: Detections at the other keyframe crossing the movement's line at less than this many eps do
#: not propose a length.
MATCH_CROSS_EPS = 2.0
#: The longest movement tried, in units of the map's extent (the widest distance between two of
#: its landmarks).
MATCH_MAX_LENGTH = 2.0
#: Candidate poses refined (the best by matched detections, one per pose).
MATCH_REFINE = 8
#: The refined pose must fit the detections it matched to this robust residual (eps).
MATCH_FIT_EPS = 2.0
#: A placement whose robust residual exceeds this many eps is not trusted for association.
PLACEMENT_MAX_EPS = 2.0


@dataclass(frozen=True)
class Matched:
    """A movement placed by :func:`match_movement`.

    Attributes
    ----------
    fit : Resection
        The least-squares pose on the matched detections, its residuals and how well they
        determine it (O1 free).
    sightings : Sightings
        The matched detections, each with its landmark's point.
    matched, runner_up : int
        Detections matched at the best pose, and at the best that tells another story.
    """

    fit: Resection
    sightings: Sightings
    matched: int
    runner_up: int


def match_movement(
    points_fl: NDArray[np.float64],
    labels: Sequence[str],
    detections: tuple[Mapping[str, Sequence[float]], Mapping[str, Sequence[float]]],
    anchor_fl: NDArray[np.float64],
    anchor_end: int,
    eps_rad: float,
) -> Matched | None:
    """Place one movement, one of whose keyframes is known, from unidentified detections.

    Parameters
    ----------
    points_fl : (k, 2) float
        The map's landmarks, FL.
    labels : list of str, length k
        Each landmark's class (its own name for a landmark of a class of its own).
    detections : (dict, dict)
        Bearings (rad) per class at O1 and at O2, relative to the movement's heading.
    anchor_fl : (2,) float
        The known keyframe's position (FL): O1 when ``anchor_end`` is 0, O2 when it is 1.
    anchor_end : int
        0 or 1.
    eps_rad : float
        Bearing error bound eps.

    Returns
    -------
    Matched or None
        None when no pose matches :data:`MATCH_MIN` detections clearly better than every
        other, or its least-squares refinement does not fit them.
    """
    pts = np.asarray(points_fl, np.float64).reshape(-1, 2)
    lab = np.asarray(labels, dtype=object)
    anchor = np.asarray(anchor_fl, np.float64).reshape(2)
    if pts.shape[0] < 2:
        return None
    ends = _flatten(detections, lab)
    tol = MATCH_TOL_EPS * eps_rad
    at_a, at_o = ends[anchor_end], ends[1 - anchor_end]
    heading = _best_headings(_headings(pts, at_a, anchor), anchor, pts, at_a, tol)
    if heading.size == 0 or at_o[0].size == 0:
        return None
    sign = 1.0 if anchor_end == 0 else -1.0  # other keyframe = anchor + sign * length * u
    extent = float(np.max(np.linalg.norm(pts[:, None, :] - pts[None, :, :], axis=-1)))
    h, t = _lengths(pts, at_o, anchor, heading, sign, MATCH_CROSS_EPS * eps_rad)
    t_ok = (t > 0.0) & (t <= MATCH_MAX_LENGTH * extent)
    h, t = h[t_ok], t[t_ok]
    if h.size == 0:
        return None
    u = np.stack((np.cos(h), np.sin(h)), axis=-1)
    other = anchor[None, :] + sign * t[:, None] * u
    pred = (_bearings(anchor[None, :], h, pts), _bearings(other, h, pts))  # (n, k) each
    count_a, pair_a = _count(pred[0], at_a, tol)
    count_o, pair_o = _count(pred[1], at_o, tol)
    score = np.where(
        (count_a >= MATCH_MIN_PER_END) & (count_o >= MATCH_MIN_PER_END), count_a + count_o, 0
    )
    found: list[_Found] = []
    for i in np.argsort(-score, kind="stable"):
        if score[i] < MATCH_MIN or len(found) == MATCH_REFINE:
            break
        if any(not f.tells_another((pair_a[i], pair_o[i])) for f in found):
            continue  # a pose already refined
        o1 = anchor if anchor_end == 0 else other[i]
        guess = MovementPose(np.array(o1, np.float64), float(h[i]), float(t[i]))
        f = _refine(pts, (at_a, at_o), anchor_end, (pair_a[i], pair_o[i]), guess, tol)
        if f is not None:
            found.append(f)
    if not found:
        return None
    best = max(found, key=lambda f: (f.count, -f.rms_rad))
    rivals = [f.count for f in found if best.rivals(f, tol)]
    runner_up = max(rivals, default=0)
    if best.count - runner_up < MATCH_LEAD:
        return None
    if robust_std(best.fit.residuals_rad) > MATCH_FIT_EPS * eps_rad:
        return None
    return Matched(best.fit, best.sightings, best.count, runner_up)


@dataclass(frozen=True)
class _Found:
    """A candidate pose refined on the detections it matched."""

    fit: Resection
    sightings: Sightings
    count: int
    rms_rad: float
    pairs: tuple[NDArray[np.int64], NDArray[np.int64]]  # anchor, other keyframe: (m,) each

    def tells_another(self, pairs: tuple[NDArray[np.int64], NDArray[np.int64]]) -> bool:
        """Whether a pose matching detections to landmarks ``pairs`` tells another story:
        matches :data:`MATCH_STORY` detections or more that this one matches too, to other
        landmarks."""
        return (
            sum(
                int(((p >= 0) & (q >= 0) & (p != q)).sum())
                for p, q in zip(self.pairs, pairs, strict=True)
            )
            >= MATCH_STORY
        )

    def rivals(self, other: _Found, tol: float) -> bool:
        """Whether ``other`` tells another story from a pose this one's fit rules out: heading
        more than ``tol`` away, or O1 or the length more than 3 std away (bearing noise std
        ``tol / 2``)."""
        if not self.tells_another(other.pairs):
            return False
        a, b = self.fit, other.fit
        std = tol / 2.0
        return bool(
            abs(float(wrap_rad(a.pose.heading_rad - b.pose.heading_rad))) > tol
            or np.linalg.norm(a.pose.o1_fl - b.pose.o1_fl) > 3.0 * std * a.position_std_fl
            or abs(np.log(a.pose.length_fl / b.pose.length_fl)) > 3.0 * std * a.log_length_std
        )


def _refine(
    pts: NDArray[np.float64],
    at: tuple[_End, _End],
    anchor_end: int,
    pairs: tuple[NDArray[np.int64], NDArray[np.int64]],
    guess: MovementPose,
    tol: float,
) -> _Found | None:
    """Least squares on the matched detections, matched again at the fit, and once more."""
    fit = None
    for _ in range(2):
        s = _sightings(pts, at, pairs, anchor_end)
        # O1 as the search's start (the known keyframe, or where the guess puts O1): a seed,
        # refined with the rest; how well the matches pin O1 is measured below
        fit = resect(s, guesses=[guess], o1_known_fl=guess.o1_fl)
        if fit is None or not np.isfinite(fit.position_std_fl):
            return None
        guess = fit.pose
        h = np.array([guess.heading_rad])
        origins = (guess.o1_fl, guess.o2_fl)
        if anchor_end == 1:
            origins = origins[::-1]
        pred = tuple(_bearings(o[None, :], h, pts) for o in origins)
        counted = [_count(p, a, tol) for p, a in zip(pred, at, strict=True)]
        pairs = (counted[0][1][0], counted[1][1][0])
    if fit is None or min(int(c[0][0]) for c in counted) < MATCH_MIN_PER_END:
        return None
    count = sum(int(c[0][0]) for c in counted)
    rms = float(np.sqrt(np.mean(fit.residuals_rad**2)))
    stds = determinacy(s, pose_params(fit.pose))  # O1 free: how well the matches pin it
    if not np.isfinite(stds[0]):
        return None
    fit = replace(fit, position_std_fl=stds[0], log_length_std=stds[1])
    return _Found(fit, s, count, rms, pairs)


_End = tuple[NDArray[np.float64], NDArray[np.bool_]]


def _flatten(
    detections: tuple[Mapping[str, Sequence[float]], Mapping[str, Sequence[float]]],
    lab: NDArray[np.object_],
) -> tuple[_End, _End]:
    """Per keyframe, the bearings (m,) of detections of a class the map holds and which
    landmarks (m, k) share each one's class."""
    out = []
    for per_class in detections:
        bearings: list[float] = []
        rows: list[NDArray[np.bool_]] = []
        for label, bs in per_class.items():
            same = lab == label
            if not same.any():
                continue
            for b in np.asarray(bs, np.float64).reshape(-1):
                if np.isfinite(b):
                    bearings.append(float(b))
                    rows.append(same)
        out.append(
            (
                np.array(bearings, np.float64),
                np.array(rows, bool).reshape(len(bearings), lab.size),
            )
        )
    return out[0], out[1]


def _headings(
    pts: NDArray[np.float64], at: _End, anchor: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Every heading (n,) that turns a detection at the anchor onto a landmark of its class."""
    b, same = at
    d = pts - anchor
    direction = np.arctan2(d[:, 1], d[:, 0])
    j, i = np.nonzero(same)
    out: NDArray[np.float64] = wrap_rad(direction[i] - b[j])
    return out


def _best_headings(
    heading: NDArray[np.float64],
    anchor: NDArray[np.float64],
    pts: NDArray[np.float64],
    at: _End,
    tol: float,
) -> NDArray[np.float64]:
    """The :data:`MATCH_HEADINGS` headings of ``heading`` (n,) that match the most detections
    at the anchor, none within ``tol`` of a better one, and each matching at least
    :data:`MATCH_MIN_PER_END`."""
    if heading.size == 0:
        return heading
    count, _ = _count(_bearings(anchor[None, :], heading, pts), at, tol)
    kept: list[float] = []
    for i in np.argsort(-count, kind="stable"):
        if count[i] < MATCH_MIN_PER_END or len(kept) == MATCH_HEADINGS:
            break
        if all(abs(float(wrap_rad(heading[i] - k))) > tol for k in kept):
            kept.append(float(heading[i]))
    return np.array(kept, np.float64)


def _lengths(
    pts: NDArray[np.float64],
    at: _End,
    anchor: NDArray[np.float64],
    heading: NDArray[np.float64],
    sign: float,
    min_cross_rad: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """For each heading, every length that turns a detection at the other keyframe onto a
    landmark of its class (ahead of it): headings (n,) and lengths (n,), flattened."""
    b, same = at
    j, i = np.nonzero(same)
    u = np.stack((np.cos(heading), np.sin(heading)), axis=-1)[:, None, :]  # (h, 1, 2)
    dirs = heading[:, None] + b[j][None, :]  # (h, p)
    v = np.stack((np.cos(dirs), np.sin(dirs)), axis=-1)  # (h, p, 2)
    rel = (pts[i] - anchor)[None, :, :]  # (1, p, 2)
    uxv = u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]
    rxv = rel[..., 0] * v[..., 1] - rel[..., 1] * v[..., 0]
    crosses = np.abs(uxv) >= np.sin(min_cross_rad)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(crosses, rxv / (sign * uxv), np.nan)
    other = anchor + sign * t[..., None] * u
    ahead = ((pts[i][None, :, :] - other) * v).sum(axis=-1) > 0.0
    keep = crosses & ahead
    hh = np.broadcast_to(heading[:, None], t.shape)
    return hh[keep], t[keep]


def _bearings(
    origins: NDArray[np.float64], heading: NDArray[np.float64], pts: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Bearings (n, k) of every landmark from origins (n or 1, 2) with headings (n,)."""
    d = pts[None, :, :] - origins[:, None, :]
    out: NDArray[np.float64] = wrap_rad(np.arctan2(d[..., 1], d[..., 0]) - heading[:, None])
    return out


def _count(
    pred: NDArray[np.float64], at: _End, tol: float
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Per pose (n), how many detections lie within ``tol`` of a landmark of their class, and
    each detection's nearest such landmark (n, m; -1 for none)."""
    b, same = at
    err = np.abs(wrap_rad(b[None, :, None] - pred[:, None, :]))  # (n, m, k)
    err = np.where(same[None, :, :], err, np.inf)
    nearest = np.argmin(err, axis=2) if b.size else np.zeros((pred.shape[0], 0), np.int64)
    ok = np.take_along_axis(err, nearest[..., None], axis=2)[..., 0] <= tol
    return ok.sum(axis=1), np.where(ok, nearest, -1)


def _sightings(
    pts: NDArray[np.float64],
    at: tuple[_End, _End],
    pairs: tuple[NDArray[np.int64], NDArray[np.int64]],
    anchor_end: int,
) -> Sightings:
    """The matched detections (anchor keyframe first) as sightings of their landmarks."""
    points, end, bearings = [], [], []
    for k, ((b, _), pair) in enumerate(zip(at, pairs, strict=True)):
        keep = pair >= 0
        points.append(pts[pair[keep]])
        end.append(np.full(int(keep.sum()), anchor_end if k == 0 else 1 - anchor_end))
        bearings.append(b[keep])
    return Sightings(
        np.concatenate(points).reshape(-1, 2),
        np.concatenate(end).astype(np.int64),
        np.concatenate(bearings),
    )


def place_left_out(
    detections: Mapping[tuple[int, int], Mapping[str, Sequence[float]]],
    poses: Mapping[tuple[int, int], KeyframePose],
    points_fl: NDArray[np.float64],
    labels: Sequence[str],
    eps_rad: float,
    sigma_rad: float,
) -> dict[tuple[int, int], KeyframePose]:
    """The keyframes of movements the map left out, placed by :func:`match_movement` from
    the keyframe of a placed neighbour where the robot turned in place (the previous
    movement's O2, else the next one's O1), outward from the placed movements.

    Parameters
    ----------
    detections : dict (movement, end) -> dict label -> bearings (rad)
        Each keyframe's detections per class (a landmark of a class of its own under its name).
    poses : dict (movement, end) -> KeyframePose
        The keyframes the map holds (FL).
    points_fl : (k, 2) float
        The map's landmarks (FL) ...
    labels : list of str, length k
        ... and their classes.
    eps_rad, sigma_rad : float
        Bearing error bound and bearing noise std, rad.

    Returns
    -------
    dict (movement, end) -> KeyframePose
        The keyframes placed, with covariances from the matched bearings alone.
    """
    placed = dict(poses)
    out: dict[tuple[int, int], KeyframePose] = {}
    left = sorted({m for m, _ in detections if (m, 0) not in poses and (m, 1) not in poses})
    while left:
        done = []
        for m in left:
            dets = (detections.get((m, 0), {}), detections.get((m, 1), {}))
            for key, end in (((m - 1, 1), 0), ((m + 1, 0), 1)):
                anchor = placed.get(key)
                if anchor is None:
                    continue
                found = match_movement(points_fl, labels, dets, anchor.origin_fl, end, eps_rad)
                if found is None:
                    continue
                ends = keyframe_poses_of(found.sightings, found.fit.pose, sigma_rad)
                if ends is not None:
                    placed[m, 0], placed[m, 1] = out[m, 0], out[m, 1] = ends
                    done.append(m)
                    break
        if not done:
            break
        left = [m for m in left if m not in done]
    return out


def place_movement(
    bearings: tuple[Mapping[str, float], Mapping[str, float]],
    points_fl: Mapping[str, NDArray[np.float64]],
    after_fl: NDArray[np.float64] | None,
    eps_rad: float,
    sigma_rad: float,
) -> tuple[MovementPose, float] | str:
    """One movement placed from bearings of identified landmarks, for association.

    Parameters
    ----------
    bearings : (dict, dict)
        Bearings (rad) at O1 and at O2 of identified landmarks, by name.
    points_fl : dict name -> (2,) float
        Where the map has the identified landmarks (FL; the reference pair included).
    after_fl : (2,) float or None
        Where the previous movement ended, when it was placed (the robot turned in place
        there): then the movement is chained on it when its bearings fit
        (:data:`PLACEMENT_MAX_EPS`).
    eps_rad, sigma_rad : float
        Bearing error bound and bearing noise std, rad.

    Returns
    -------
    (MovementPose, float) or str
        The pose and O1's position std (FL), else why it cannot be placed.
    """
    pts, ends, bs = [], [], []
    for end, bmap in enumerate(bearings):
        for name, b in bmap.items():
            if name in points_fl and math.isfinite(b):
                pts.append(points_fl[name])
                ends.append(end)
                bs.append(float(b))
    s = Sightings(np.array(pts, np.float64).reshape(-1, 2), np.array(ends, np.int64), np.array(bs))
    n1, n2 = int((s.end == 0).sum()), int((s.end == 1).sum())
    if after_fl is not None and n1 >= 1 and n2 >= 1:
        chained = place_chained(s, after_fl, sigma_rad)
        if chained is not None:
            r = s.residuals(pose_params(chained[0]))
            if robust_std(r) <= PLACEMENT_MAX_EPS * eps_rad:
                return chained
    if not (n1 >= 1 and n2 >= 1 and n1 + n2 >= 4):
        return f"too few bearings of mapped landmarks to place it ({n1} at O1, {n2} at O2)"
    found = resect(s, guesses=[])
    if found is None:
        return "cannot be placed"
    robust = robust_std(found.residuals_rad)
    if robust <= PLACEMENT_MAX_EPS * eps_rad and math.isfinite(found.position_std_fl):
        return found.pose, found.position_std_fl * sigma_rad
    return f"placement does not fit the map (robust residual {deg_text(robust)})"


def misplaced(
    unique: Mapping[tuple[int, int], Mapping[str, float]],
    poses: Mapping[tuple[int, int], KeyframePose],
    points_fl: NDArray[np.float64],
    labels: Sequence[str],
    tol_rad: float,
) -> set[int]:
    """The movements a keyframe of which ``poses`` holds where a landmark of a class of its own
    is seen more than ``tol_rad`` from where the map puts it.

    Parameters
    ----------
    unique : dict (movement, end) -> dict name -> bearing (rad)
        Each keyframe's bearings of landmarks of a class of their own (robot frame).
    poses : dict (movement, end) -> KeyframePose
        The keyframes the map holds (FL).
    points_fl : (k, 2) float
        The map's landmarks (FL) ...
    labels : list of str, length k
        ... and their classes (a landmark of a class of its own under its name).
    tol_rad : float
        The largest miss (rad).

    Returns
    -------
    set of int
        The movements: a landmark of a class of its own, seen where no other landmark can be
        taken for it, contradicts the keyframe's pose (a heading or position the keyframe's
        other bearings, of look-alike landmarks given the wrong names, hold it at).
    """
    where = {label: points_fl[i] for i, label in enumerate(labels)}
    out: set[int] = set()
    for key, bearings in unique.items():
        pose = poses.get(key)
        names = [n for n in bearings if n in where]
        if pose is None or not names:
            continue
        pts = np.array([where[n] for n in names])
        seen = _bearings(pose.origin_fl[None, :], np.array([pose.heading_rad]), pts)[0]
        if float(np.abs(wrap_rad(np.array([bearings[n] for n in names]) - seen)).max()) > tol_rad:
            out.add(key[0])
    return out


def matching_map(
    mapped: Mapping[str, LandmarkEstimate],
    reference: tuple[str, str],
    alike: Collection[str],
    known: Sequence[tuple[str, LandmarkEstimate]],
) -> tuple[NDArray[np.float64], list[str]]:
    """The map to match detections with: points (k, 2) FL and their classes. The reference
    pair, then each landmark of ``mapped`` of a class of its own (not one of the ``alike``
    names) under its name, then ``known``: (class, estimate) of each named landmark of a
    shared class."""
    pts = [np.zeros(2), np.array([1.0, 0.0])]
    labels = list(reference)
    for n, e in mapped.items():
        if n not in alike and n not in reference:
            pts.append(e.mean_fl)
            labels.append(n)
    for label, e in known:
        pts.append(e.mean_fl)
        labels.append(label)
    return np.array(pts, np.float64).reshape(-1, 2), labels


def all_detections(
    unique: Mapping[str, float],
    per_class: Mapping[str, Sequence[float]],
    known: Collection[str],
) -> dict[str, Sequence[float]]:
    """One keyframe's detections per class for matching: each identified bearing whose name is
    in ``known`` as a class of its own, then the detections of the shared classes."""
    return {**{n: [b] for n, b in unique.items() if n in known}, **per_class}
