"""Per-movement association of landmarks that look alike: place, predict, assign, hypothesize.

For each movement (its two keyframes, O1 and O2):

1. Place the movement from the bearings of landmarks whose class is their own (the reference
   pair included) and their map estimates: chained on the end of the previous movement when
   that one was placed (one bearing at each keyframe suffices), else by resection
   (:func:`pipeline.geometry.resect`, four bearings at least); when these are too few
   after a placed movement, by matching every detection with the map
   (:func:`pipeline.association.match.match_movement`).
2. Per shared class, predict the bearing of each landmark already named (``red#1``, ...) from
   O1 and O2, with its std from the map covariance, the placement and the bearing noise, and
   assign the class's detections (:func:`pipeline.association.assign.assign`). Names in the
   map and confirmed (:attr:`pipeline.association.support.Support.confirmed`) also give their
   distances: of several predicted in line (within eps) on one blob, the one clearly in
   front takes it and hides the others.
3. Detections no named landmark explains, or that the assignment left contested, feed the
   hypotheses of the class: a hypothesis whose gate holds one detection gains that ray (if
   the rays still meet); one with none counts a miss. Pairs of detections still unexplained,
   one from each keyframe, whose rays meet ahead of both start new hypotheses (every pairing
   the two cones allow). Rays kept from earlier movements are placed anew on the estimator's
   current trajectory.
4. A hypothesis seen along four distinct lines of sight over two movements, every ray within
   eps of its point, is confirmed unless a rival sharing one of its rays still disputes it: it
   is named ``label#k`` (k in order of confirmation) while the class has fewer named landmarks
   than the catalog has; hypotheses sharing a ray with it are dropped. A hypothesis whose
   every ray is a bearing of a named landmark is that landmark seen again (dropped). A
   hypothesis that misses :data:`MAX_MISSES` keyframes, or is not confirmed within
   :data:`MAX_AGE` movements, is dropped.
   The detections no name took are kept for :data:`DISCOVER_WINDOW` movements; when the rays
   of many of them, from many keyframes, pass near one point (a landmark whose rays the
   hypotheses kept disputing or swallowing, or one seen only from a narrow fan of directions,
   along too few lines of sight for a hypothesis), that point is named too.

5. What became of each named landmark's predictions since it was named (seen, missed,
   contested, too uncertain; hidden behind a nearer one is not a test) is counted
   (:mod:`pipeline.association.support`); a name seen too rarely, or whose bearings in the
   joint map scatter too widely about it, is reported as doubtful every movement while it
   stays so, a name not seen often enough since its naming to tell as unconfirmed. When the
   class's catalog is full and a hypothesis is confirmed, the most doubtful name is retracted
   and given to it.

Whatever is left unresolved (contested detections, unexplained detections, a class beyond its
catalog count, a movement that cannot be placed, a doubtful name) is reported in the movement's
result.

6. Once the log is processed, :meth:`Associator.place_left_out` places the movements the map
   left out by matching, :meth:`Associator.associate_final` associates every keyframe's
   detections again with the final map (:mod:`pipeline.association.final`), and
   :meth:`Associator.repair_final` gives a doubtful name to a landmark the detections it leaves
   unexplained point at.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad
from pipeline.association.assign import GATE_CHI2, Assignment, assign
from pipeline.association.final import (
    FinalDetection,
    associate_final,
    meeting_point,
    missing_reports,
    unexplained_rays,
)
from pipeline.association.hypotheses import (
    FIT_TOL_EPS,
    MIN_PARALLAX_EPS,
    Hypothesis,
    Ray,
    RaySet,
    cannot_meet,
    fit,
)
from pipeline.association.match import Matched, match_movement, place_left_out
from pipeline.association.predict import (
    MAX_PRED_STD_EPS,
    outside_view,
    predict_bearings,
    predict_ranges,
)
from pipeline.association.support import Outcome, Support
from pipeline.crb import truncated_gaussian_std
from pipeline.estimate import LandmarkEstimate
from pipeline.geometry import KeyframePose, MovementPose, Sightings, pose_params, resect
from pipeline.joint.noise import robust_std

#: A hypothesis missing from this many keyframes where it was predicted is dropped.
MAX_MISSES = 2
#: ... as is one not confirmed within this many movements of its birth.
MAX_AGE = 8
#: A placement whose robust residual exceeds this many eps is not trusted for association.
PLACEMENT_MAX_EPS = 2.0
#: Rays are placed anew when the estimator moved their keyframe this much (FL) or turned it
#: by a tenth of the bearing noise std.
MOVED_FL = 1e-3
#: Live hypotheses kept per class (the best seen along most lines of sight, then by RMS ray
#: error).
MAX_HYPOTHESES = 200
#: Distinct lines of sight (through its point, differing by more than :data:`DISTINCT_EPS`
#: eps) and movements a hypothesis needs to be confirmed.
CONFIRM_POSITIONS = 4
CONFIRM_MOVEMENTS = 2
DISTINCT_EPS = 2.0
#: A landmark the hypotheses did not name is named from the unnamed detections of the last
#: DISCOVER_WINDOW movements when their rays pass within FIT_TOL_EPS eps of one point from
#: DISCOVER_KEYFRAMES keyframes, along DISCOVER_LINES distinct lines of sight over
#: DISCOVER_MOVEMENTS movements, and the point's class was detected at DISCOVER_SEEN_SHARE of
#: the keyframes since the first of them where it could be predicted.
DISCOVER_WINDOW = 10
DISCOVER_KEYFRAMES = 8
DISCOVER_LINES = 4
DISCOVER_MOVEMENTS = 3
DISCOVER_SEEN_SHARE = 0.8
#: A point whose rays span only DISCOVER_LINES - 1 lines of sight (a landmark at the arena's
#: edge, seen from a narrow fan of directions) is named when they come from this many keyframes
#: and its class was detected at DISCOVER_FAN_SEEN_SHARE of the keyframes where predicted.
DISCOVER_FAN_KEYFRAMES = 12
DISCOVER_FAN_SEEN_SHARE = 0.9
#: Once the log is processed, the names of a class under suspicion (its doubtful ones; then the
#: one, then the REBUILD_SUSPECTS, the final map does not hold or, after those, gives a
#: detection at the smallest share of their predictions) are given anew where their detections
#: and those the final map left unexplained meet, when those points explain REBUILD_GAIN
#: detections more than the names do.
REBUILD_SUSPECTS = 2
REBUILD_GAIN = 8
#: A hypothesis sharing a ray with another is confirmed only when seen along this many more
#: lines of sight than it.
RIVAL_LEAD = 2
#: ... or from as many, with an RMS ray error this many times smaller.
RIVAL_RMS_RATIO = 2.0


#: Once the log is processed, a point the unexplained detections meet at is a named landmark
#: seen again only when also this close to it (squared Mahalanobis distance with both
#: covariances; chi-square, 2 dof, 99.9 %): from many keyframes a landmark lines up with a named
#: one a few degrees away, whose gate then holds most of its rays, though the final map told them
#: apart.
FINAL_APART_CHI2 = 13.82


def slot_name(label: str, k: int) -> str:
    """The name of the ``k``-th confirmed landmark of class ``label`` (``red#1``)."""
    return f"{label}#{k}"


@dataclass
class MovementAssociation:
    """What association did for one movement.

    Attributes
    ----------
    index : int
        The movement.
    bearings_o1_rad, bearings_o2_rad : dict name -> float
        Bearings given to named landmarks of shared classes at O1 and O2 (rad).
    names : dict label -> (list, list)
        Per class, the name given to each detection at O1 and at O2 (None: not associated),
        in the order of the detections passed in.
    confirmed : list of str
        Landmarks named with this movement.
    history : dict name -> list of (movement, end, bearing_rad)
        Bearings of the landmarks named with this movement from earlier movements (for an
        estimator that can take them late).
    unresolved : dict key -> str
        Ambiguities not resolved (key: a landmark name or a class label, with the keyframe).
    not_visible : dict name -> str
        Named landmarks predicted but not detected (hidden behind another, out of range).
    outcomes : dict name -> list of str
        Per named landmark predicted at this movement's keyframes, what became of each
        prediction (:data:`~pipeline.association.support.Outcome`).
    doubtful : dict name -> str
        Named landmarks whose predictions since their naming were too rarely seen, or whose
        bearings in the map scatter too widely
        (:meth:`~pipeline.association.support.Support.doubt`), with why; also in
        ``unresolved`` (key ``"<name> doubtful"``).
    unconfirmed : dict name -> str
        Named landmarks, not doubtful, seen at too few keyframes since their naming to confirm
        the name (:meth:`~pipeline.association.support.Support.unconfirmed`), with why; names
        given with this movement included.
    retracted : dict name -> str
        Doubtful names taken back with this movement and given to a landmark a full catalog
        kept out, or once the log is processed names under suspicion given anew (in
        ``confirmed`` too; the estimator must forget the old landmark before it takes
        ``history``); also in ``unresolved`` (key ``"<name> retracted"``).
    named_at_end : dict name -> str
        Once the log is processed (:meth:`Associator.repair_final`): free names given to
        landmarks the final map's unexplained detections point at (in ``confirmed`` too),
        with why.
    n_hypotheses : int
        Live hypotheses after this movement.
    pose : MovementPose or None
        The placement used (None: the movement could not be placed).
    """

    index: int
    bearings_o1_rad: dict[str, float] = field(default_factory=dict)
    bearings_o2_rad: dict[str, float] = field(default_factory=dict)
    names: dict[str, tuple[list[str | None], list[str | None]]] = field(default_factory=dict)
    confirmed: list[str] = field(default_factory=list)
    history: dict[str, list[tuple[int, int, float]]] = field(default_factory=dict)
    unresolved: dict[str, str] = field(default_factory=dict)
    not_visible: dict[str, str] = field(default_factory=dict)
    outcomes: dict[str, list[Outcome]] = field(default_factory=dict)
    doubtful: dict[str, str] = field(default_factory=dict)
    unconfirmed: dict[str, str] = field(default_factory=dict)
    retracted: dict[str, str] = field(default_factory=dict)
    named_at_end: dict[str, str] = field(default_factory=dict)
    n_hypotheses: int = 0
    pose: MovementPose | None = None


def _deg(x: float) -> str:
    return f"{math.degrees(x):.1f} deg"


class Associator:
    """Names detections of shared classes across movements (see the module docstring).

    Parameters
    ----------
    classes : mapping label -> int
        Each shared class and how many catalog landmarks have it (the most that may be named).
    reference : (str, str)
        The reference pair, at (0, 0) and (1, 0) in FL.
    vision_error_rad : float
        The bearing error bound eps.
    field_of_view_rad : (lo, hi) or None
        A pinhole camera's view, bearings of its right and left edges (rad, robot frame): a
        landmark predicted outside it (beyond its gate) is not visible there, neither seen nor
        missed. None: a panoramic camera.
    """

    def __init__(
        self,
        classes: Mapping[str, int],
        reference: tuple[str, str],
        *,
        vision_error_rad: float,
        field_of_view_rad: tuple[float, float] | None = None,
    ) -> None:
        self.field_of_view_rad = field_of_view_rad
        self.capacity = dict(classes)
        self.reference = reference
        self.eps_rad = float(vision_error_rad)
        self.sigma_rad = truncated_gaussian_std(self.eps_rad)
        self.named: dict[str, list[str]] = {c: [] for c in self.capacity}
        self.hypotheses: dict[str, list[Hypothesis]] = {c: [] for c in self.capacity}
        #: named landmarks the estimator has not mapped yet: their rays, refitted as they grow
        self.unmapped: dict[str, Hypothesis] = {}
        #: what became of each named landmark's predictions since it was named
        self.support: dict[str, Support] = {}
        self._last: tuple[int, MovementPose] | None = None
        self._dets: dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]] = {}
        #: every detection of each shared class at each keyframe (movement, end) so far
        self._seen_at: dict[tuple[int, int], dict[str, NDArray[np.float64]]] = {}
        #: per class, detections no name took: (movement, end, detection, bearing_rad)
        self._unnamed: dict[str, list[tuple[int, int, int, float]]] = {c: [] for c in classes}
        #: the estimator's placement of each movement (index -> pose), as of the last one
        self._trajectory: dict[int, MovementPose] = {}
        self._free: dict[str, tuple[list[int], list[int]]] = {}
        self._distinct = DISTINCT_EPS * self.eps_rad

    @property
    def names(self) -> list[str]:
        """Every name a landmark of a shared class may get, class by class (``red#1`` ...)."""
        return [slot_name(c, k + 1) for c, n in self.capacity.items() for k in range(n)]

    def associate_final(
        self,
        detections: Mapping[tuple[int, int], Mapping[str, Sequence[float]]],
        poses: Mapping[tuple[int, int], KeyframePose],
        mapped: Mapping[str, LandmarkEstimate],
        noise_rad: float | None = None,
    ) -> tuple[list[FinalDetection], dict[str, str]]:
        """Every keyframe's detections associated with the final map (the estimator's
        ``mapped`` landmarks and keyframe ``poses``) under the names given so far
        (:func:`pipeline.association.final.associate_final`), and per class (every name of it
        given or not) a report when the final map leaves too many of its detections unexplained
        (:func:`pipeline.association.final.missing_reports`). ``noise_rad``: the map's
        bearing noise std (default the one eps implies)."""
        known = {
            label: [(n, mapped[n]) for n in self.named[label] if n in mapped]
            for label in self.capacity
        }
        final = associate_final(
            detections,
            poses,
            known,
            noise_rad=self.sigma_rad if noise_rad is None else noise_rad,
            eps_rad=self.eps_rad,
        )
        given = {c: (len(self.named[c]), n) for c, n in self.capacity.items()}
        return final, missing_reports(final, given, poses, self.eps_rad)

    def place_left_out(
        self,
        unique: Mapping[tuple[int, int], Mapping[str, float]],
        detections: Mapping[tuple[int, int], Mapping[str, Sequence[float]]],
        poses: Mapping[tuple[int, int], KeyframePose],
        mapped: Mapping[str, LandmarkEstimate],
        noise_rad: float | None = None,
    ) -> dict[tuple[int, int], KeyframePose]:
        """Once the log is processed: the keyframes of movements the map left out (before the
        map began, or too few of their detections identified), placed for the association
        with the final map by matching every detection with it, from a placed neighbour
        (:func:`pipeline.association.match.place_left_out`).

        ``unique``: each keyframe's bearings of landmarks of a class of their own (rad);
        ``detections``: its detections per shared class; ``poses`` and ``mapped``: the final
        map; ``noise_rad``: its bearing noise std (default the one eps implies)."""
        pts, labels = self._matching_map(mapped)
        own = set(labels)
        per_keyframe = {
            key: _all_detections(unique.get(key, {}), detections.get(key, {}), own)
            for key in set(unique) | set(detections)
        }
        return place_left_out(
            per_keyframe,
            poses,
            pts,
            labels,
            self.eps_rad,
            self.sigma_rad if noise_rad is None else noise_rad,
        )

    def _matching_map(
        self, mapped: Mapping[str, LandmarkEstimate]
    ) -> tuple[NDArray[np.float64], list[str]]:
        """The map to match detections with: points (k, 2) FL and their classes (a landmark of
        a class of its own: its name; the reference pair included)."""
        alike = {n for names in self.named.values() for n in names}
        pts = [np.zeros(2), np.array([1.0, 0.0])]
        labels = list(self.reference)
        for n, e in mapped.items():
            if n not in alike and n not in self.reference:
                pts.append(e.mean_fl)
                labels.append(n)
        for label in self.capacity:
            for _, e in self._known(label, mapped):
                pts.append(e.mean_fl)
                labels.append(label)
        return np.array(pts, np.float64).reshape(-1, 2), labels

    def repair_final(
        self,
        final: Sequence[FinalDetection],
        poses: Mapping[tuple[int, int], KeyframePose],
        mapped: Mapping[str, LandmarkEstimate],
        index: int,
    ) -> MovementAssociation | None:
        """Once the log is processed, per class, where the detections the final map leaves
        unexplained meet at one point as a search names a landmark (:meth:`_final_point`):
        with names of the class still free, the point gets the next one (and the rest of the
        rays are searched again while names are free: ``named_at_end``); with every name given
        and one doubtful, a doubtful name is retracted and given to the point (as
        :meth:`hypothesize` does with a full catalog): the one the final association gave a
        detection at the smallest share of the keyframes where the final map predicts it
        (:meth:`_final_share`). When neither gives a name, names under suspicion may be given
        anew (:meth:`_rebuild`).

        ``final`` is :meth:`associate_final`'s association, ``poses`` and ``mapped`` the final
        map, ``index`` the last movement. Returns what changed (``retracted``,
        ``named_at_end``, ``confirmed``, ``history``: the estimator forgets the retracted
        landmarks, takes the history and settles), or None when nothing did."""
        out = MovementAssociation(index + 1)  # after the last movement: no ray is its own
        for label, count in self.capacity.items():
            full = len(self.named[label]) >= count
            given = len(out.confirmed)
            rays = unexplained_rays(final, label, poses)
            while (not full or self._most_doubtful(label) is not None) and (
                found := self._final_point(label, rays, mapped)
            ) is not None:
                h, lines = found
                out.names.setdefault(label, ([], []))
                if full:
                    weakest = min(
                        (n for n in self.named[label] if self.support[n].doubt() is not None),
                        key=lambda n: self._final_share(n, final, poses, mapped),
                    )
                    self._give_name(label, h, lines, out, searched=True, retract=weakest)
                    break
                self._give_name(label, h, lines, out, searched=True)
                x, y = h.point_fl
                out.named_at_end[out.confirmed[-1]] = (
                    f"named once the log was processed: {len(h.rays)} detections the final map "
                    f"left unexplained, from {len({(r.movement, r.end) for r in h.rays})} "
                    f"keyframes along {lines} lines of sight, meet at ({x:.2f}, {y:.2f}) FL"
                )
                full = len(self.named[label]) >= count
                if full:
                    break
                rays = [r for r in rays if (r.movement, r.end, r.detection) not in h.keys]
            if len(out.confirmed) == given:
                self._rebuild(label, final, poses, mapped, out)
        return out if out.confirmed else None

    def _rebuild(
        self,
        label: str,
        final: Sequence[FinalDetection],
        poses: Mapping[tuple[int, int], KeyframePose],
        mapped: Mapping[str, LandmarkEstimate],
        out: MovementAssociation,
    ) -> None:
        """Give names of ``label`` under suspicion anew (:data:`REBUILD_SUSPECTS`): where their
        detections and the ones the final map leaves unexplained meet (:meth:`_final_point`,
        one point per name at most), when the points explain :data:`REBUILD_GAIN` detections
        more than the names do; each point gets the name nearest to it, unless within
        :data:`FINAL_APART_CHI2` of it already."""
        share = {n: self._final_share(n, final, poses, mapped) for n in self.named[label]}
        weakest = sorted(share, key=lambda n: (n in mapped, share[n]))  # unmapped: none given
        doubtful = [n for n in self.named[label] if self.support[n].doubt() is not None]
        suspects = [doubtful] if doubtful else []
        suspects += [weakest[:k] for k in range(1, REBUILD_SUSPECTS + 1)]
        for names in suspects:
            rays = unexplained_rays(final, label, poses, names)
            found: list[tuple[Hypothesis, int]] = []
            while (
                len(found) < len(names)
                and (f := self._final_point(label, rays, mapped, apart_from=names)) is not None
            ):
                found.append(f)
                rays = [r for r in rays if (r.movement, r.end, r.detection) not in f[0].keys]
            before = sum(d.name in names for d in final)
            explained = sum(len(h.rays) for h, _ in found)
            if explained >= before + REBUILD_GAIN:
                break
        else:
            return
        pairs = sorted(
            (float(np.sum((h.point_fl - mapped[n].mean_fl) ** 2)) if n in mapped else np.inf, k, n)
            for k, (h, _) in enumerate(found)
            for n in names
        )
        given: dict[int, str] = {}
        for _, k, n in pairs:
            if k not in given and n not in given.values():
                given[k] = n
        given = {k: n for k, n in given.items() if not self._stays(found[k][0], mapped.get(n))}
        out.names.setdefault(label, ([], []))
        for k, n in given.items():
            h, lines = found[k]
            x, y = h.point_fl
            seen = (
                f"given a detection at {100 * share[n]:.0f} % of the keyframes where predicted"
                if n in mapped
                else "not in the final map (its bearings never met at one point)"
            )
            why = (
                f"{self.support[n].doubt() or seen}; given anew once the log was processed: "
                f"with the detections the final map left unexplained, those of "
                f"{', '.join(names)} meet at {len(found)} point(s), which explain "
                f"{explained} detections against {before}; this one "
                f"at ({x:.2f}, {y:.2f}) FL along {lines} lines of sight"
            )
            self._give_name(label, h, lines, out, searched=True, retract=n, why=why)

    def _final_point(
        self,
        label: str,
        rays: Sequence[Ray],
        mapped: Mapping[str, LandmarkEstimate],
        apart_from: Collection[str] = (),
    ) -> tuple[Hypothesis, int] | None:
        """Where ``rays`` (unexplained by the final map) meet as the search names a landmark:
        :data:`DISCOVER_KEYFRAMES` keyframes, :data:`DISCOVER_LINES` lines of sight over
        :data:`DISCOVER_MOVEMENTS` movements, every ray within eps, not a named landmark seen
        again (mostly its rays and within :data:`FINAL_APART_CHI2` of it); the fitted point and
        its lines of sight, or None."""
        met = meeting_point(rays, self.eps_rad)
        if met is None or len(met[1]) < DISCOVER_KEYFRAMES:
            return None
        h = fit(label, met[1], self.eps_rad, self.sigma_rad, met[0])
        if h is None or (lines := h.lines_of_sight(self._distinct)) < DISCOVER_LINES:
            return None
        if len({r.movement for r in h.rays}) < DISCOVER_MOVEMENTS:
            return None
        for n, e in self._known(label, mapped):
            if n in apart_from:
                continue
            if self._stays(h, e) and 2 * sum(self._ray_fits(r, e) for r in h.rays) > len(h.rays):
                return None  # mostly bearings of a named landmark: that one, left unexplained
        return h, lines

    @staticmethod
    def _stays(h: Hypothesis, e: LandmarkEstimate | None) -> bool:
        """Whether ``h`` is within :data:`FINAL_APART_CHI2` of ``e`` (False: no ``e``)."""
        if e is None:
            return False
        d = h.point_fl - e.mean_fl
        return float(d @ np.linalg.solve(h.cov_fl + e.cov_fl, d)) <= FINAL_APART_CHI2

    def _final_share(
        self,
        name: str,
        final: Sequence[FinalDetection],
        poses: Mapping[tuple[int, int], KeyframePose],
        mapped: Mapping[str, LandmarkEstimate],
    ) -> float:
        """Share of the keyframes where the final map predicts ``name`` sharply enough to
        gate at which the final association gave it a detection (1 when not in the map)."""
        e = mapped.get(name)
        if e is None or not poses:
            return 1.0
        predicted = 0
        for p in poses.values():
            _, std = predict_bearings(
                p.origin_fl,
                p.heading_rad,
                e.mean_fl[None, :],
                e.cov_fl[None, :, :],
                bearing_var_rad=self.sigma_rad**2,
                pose_cov=p.cov,
            )
            predicted += bool(std[0] <= MAX_PRED_STD_EPS * self.eps_rad)
        return sum(d.name == name for d in final) / max(predicted, 1)

    # ------------------------------------------------------------------ placement
    def _place(
        self,
        index: int,
        bearings: tuple[Mapping[str, float], Mapping[str, float]],
        mapped: Mapping[str, LandmarkEstimate],
        *,
        match: bool = False,
    ) -> tuple[MovementPose, float] | str:
        """The movement's pose and O1's position std (FL) from identified bearings (chained on
        the last movement, else by resection), else with ``match`` and a chained movement by
        matching every detection with the map; else why it cannot be placed."""
        points = {self.reference[0]: np.zeros(2), self.reference[1]: np.array([1.0, 0.0])}
        points.update({n: e.mean_fl for n, e in mapped.items() if n not in self.reference})
        pts, ends, bs = [], [], []
        for end, bmap in enumerate(bearings):
            for name, b in bmap.items():
                if name in points and math.isfinite(b):
                    pts.append(points[name])
                    ends.append(end)
                    bs.append(float(b))
        s = Sightings(
            np.array(pts, np.float64).reshape(-1, 2), np.array(ends, np.int64), np.array(bs)
        )
        n1, n2 = int((s.end == 0).sum()), int((s.end == 1).sum())
        few = f"too few bearings of mapped landmarks to place it ({n1} at O1, {n2} at O2)"
        last = self._last[1] if self._last is not None and self._last[0] == index - 1 else None
        if last is not None and n1 >= 1 and n2 >= 1:
            chained = _place_chained(s, last.o2_fl, self.sigma_rad)
            if chained is not None:
                r = s.residuals(pose_params(chained[0]))
                if robust_std(r) <= PLACEMENT_MAX_EPS * self.eps_rad:
                    return chained
        if n1 >= 1 and n2 >= 1 and n1 + n2 >= 4:
            found = resect(s, guesses=[])
            if found is None:
                why = "cannot be placed"
            else:
                robust = robust_std(found.residuals_rad)
                if robust <= PLACEMENT_MAX_EPS * self.eps_rad and math.isfinite(
                    found.position_std_fl
                ):
                    return found.pose, found.position_std_fl * self.sigma_rad
                why = f"placement does not fit the map (robust residual {_deg(robust)})"
        else:
            why = few
        if last is None or not match:
            return why
        matched = self._match(bearings, mapped, last.o2_fl)
        if matched is None:
            return f"{why}; its detections match the map nowhere clearly"
        return matched.fit.pose, matched.fit.position_std_fl * self.sigma_rad

    def _match(
        self,
        bearings: tuple[Mapping[str, float], Mapping[str, float]],
        mapped: Mapping[str, LandmarkEstimate],
        o1_fl: NDArray[np.float64],
    ) -> Matched | None:
        """The movement placed by matching every detection (identified or of a shared class)
        with the map, from O1 where the last movement ended (:func:`match_movement`)."""
        pts, labels = self._matching_map(mapped)
        own = set(labels)
        per_class = [{c: d[end].tolist() for c, d in self._dets.items()} for end in (0, 1)]
        o1, o2 = (_all_detections(b, c, own) for b, c in zip(bearings, per_class, strict=True))
        return match_movement(pts, labels, (o1, o2), o1_fl, 0, self.eps_rad)

    # ------------------------------------------------------------------ one movement
    def associate(
        self,
        index: int,
        unique: tuple[Mapping[str, float], Mapping[str, float]],
        detections: tuple[Mapping[str, Sequence[float]], Mapping[str, Sequence[float]]],
        mapped: Mapping[str, LandmarkEstimate],
    ) -> MovementAssociation:
        """Name one movement's detections of shared classes after the landmarks already named.

        Call :meth:`hypothesize` once the estimator has placed the movement.

        Parameters
        ----------
        index : int
            The movement (consecutive indices are chained by a turn in place).
        unique : (dict, dict)
            Bearings (rad) at O1 and at O2 of landmarks whose class is their own.
        detections : (dict, dict)
            Per shared class label, the bearings (rad) of its detections at O1 and at O2.
        mapped : dict name -> LandmarkEstimate
            The estimator's current map (FL), named landmarks of shared classes included.
        """
        out = MovementAssociation(index)
        self._dets = {
            c: (
                np.asarray(detections[0].get(c, ()), np.float64),
                np.asarray(detections[1].get(c, ()), np.float64),
            )
            for c in self.capacity
        }
        self._free = {c: ([], []) for c in self.capacity}
        for c, (d1, d2) in self._dets.items():
            out.names[c] = ([None] * d1.size, [None] * d2.size)
        for end in (0, 1):
            self._seen_at[index, end] = {c: d[end] for c, d in self._dets.items()}
        placed = self._place(index, unique, mapped, match=True)
        if isinstance(placed, str):
            for c, (d1, d2) in self._dets.items():
                if d1.size + d2.size:
                    out.unresolved[c] = (
                        f"{d1.size + d2.size} detection(s) not associated: movement {placed}"
                    )
            self._weigh(out)
            out.n_hypotheses = sum(len(h) for h in self.hypotheses.values())
            return out
        for _ in range(2):  # placed from the unique landmarks, then with the named ones too
            pose, pos_std = placed
            out = self._assign_named(index, pose, pos_std, mapped)
            both = tuple(
                {**u, **b}
                for u, b in zip(unique, (out.bearings_o1_rad, out.bearings_o2_rad), strict=True)
            )
            if not (out.bearings_o1_rad or out.bearings_o2_rad):
                break
            known = {
                **{n: LandmarkEstimate(h.point_fl, h.cov_fl) for n, h in self.unmapped.items()},
                **mapped,
            }
            again = self._place(index, (both[0], both[1]), known)
            if isinstance(again, str):
                break
            placed = again
        self._weigh(out)
        out.n_hypotheses = sum(len(h) for h in self.hypotheses.values())
        return out

    def _weigh(self, out: MovementAssociation) -> None:
        """Count the outcomes of this movement's predictions; report doubtful and unconfirmed
        names."""
        for name, outcomes in out.outcomes.items():
            support = self.support.get(name)
            if support is not None and support.named_at < out.index:
                for outcome in outcomes:
                    support.add(outcome)
        self._report(out)

    def _report(self, out: MovementAssociation) -> None:
        """Report the doubtful and the unconfirmed names (as of now) in ``out``."""
        for name, support in self.support.items():
            out.doubtful.pop(name, None)
            out.unresolved.pop(f"{name} doubtful", None)
            out.unconfirmed.pop(name, None)
            why = support.doubt()
            if why is not None:
                out.doubtful[name] = why
                out.unresolved[f"{name} doubtful"] = why
            elif (young := support.unconfirmed()) is not None:
                out.unconfirmed[name] = young

    def _assign_named(
        self, index: int, pose: MovementPose, pos_std: float, mapped: Mapping[str, LandmarkEstimate]
    ) -> MovementAssociation:
        out = MovementAssociation(index, pose=pose)
        origins = (pose.o1_fl, pose.o2_fl)
        for c, dets in self._dets.items():
            out.names[c] = ([None] * dets[0].size, [None] * dets[1].size)
            if dets[0].size + dets[1].size == 0:
                continue
            self._free[c] = self._class(c, dets, origins, pose.heading_rad, pos_std**2, mapped, out)
        return out

    def hypothesize(
        self,
        out: MovementAssociation,
        pose: MovementPose | None,
        mapped: Mapping[str, LandmarkEstimate],
        trajectory: Mapping[int, MovementPose] | None = None,
        scatter: Mapping[str, tuple[int, float]] | None = None,
    ) -> None:
        """Grow, start, confirm and drop hypotheses with this movement's free detections;
        search the unnamed detections of the last movements for a landmark they missed.

        ``pose`` is the movement as the estimator placed it (None: not placed; then the
        association's own placement is used, if any), ``mapped`` the estimator's map after it,
        ``trajectory`` the estimator's current placement of earlier movements (index -> pose):
        rays kept from them are placed anew (early placements, from few landmarks, are
        rough). ``scatter`` is how widely each mapped name's bearings scatter about it
        (:attr:`pipeline.joint.JointSlam.bearing_scatter`; a name that scatters too widely is
        doubtful). Landmarks named now are in ``out.confirmed`` and their bearings in
        ``out.history``; the doubtful and unconfirmed names are reported anew.
        """
        for named, support in self.support.items():
            support.scatter = (scatter or {}).get(named)
        pose = pose or out.pose
        if pose is None:
            self._report(out)
            return
        if trajectory:
            self._replace(trajectory)
            self._trajectory = dict(trajectory)
        self._trajectory[out.index] = pose
        for key in [k for k in self._seen_at if k[0] <= out.index - DISCOVER_WINDOW]:
            del self._seen_at[key]  # older than any ray the search keeps
        self._last = (out.index, pose)
        origins = (pose.o1_fl, pose.o2_fl)
        index = out.index
        for c, dets in self._dets.items():
            for end in (0, 1):
                for j, name in enumerate(out.names[c][end]):
                    if name is not None and name in self.unmapped:
                        ray = Ray.placed(
                            index, end, j, float(dets[end][j]), origins[end], pose.heading_rad
                        )
                        self.unmapped[name].rays.append(ray)
            for name in self.named[c]:
                h = self.unmapped.get(name)
                refit = h and fit(c, h.rays, self.eps_rad, self.sigma_rad)
                if refit:
                    self.unmapped[name] = refit
            free = [list(f) for f in self._free[c]]
            if not self.hypotheses[c] and not free[0] and not free[1]:
                continue
            free = self._grow(c, dets, free, origins, pose.heading_rad, index)
            self._birth(c, dets, free, origins, pose.heading_rad, index)
            self._confirm(c, out, mapped)
            self._keep_unnamed(c, out)
            self._discover(c, out, mapped)
            left = [f"{len(f)} at {w}" for f, w in zip(free, ("O1", "O2"), strict=True) if f]
            if left:
                out.unresolved.setdefault(
                    f"{c} unexplained",
                    f"{', '.join(left)} detection(s) of {c} explained by no named landmark "
                    f"({len(self.hypotheses[c])} hypothesis(es) of {c} open)",
                )
        out.n_hypotheses = sum(len(h) for h in self.hypotheses.values())
        self._report(out)

    def _known(
        self, label: str, mapped: Mapping[str, LandmarkEstimate]
    ) -> list[tuple[str, LandmarkEstimate]]:
        out = []
        for name in self.named[label]:
            if name in mapped:
                self.unmapped.pop(name, None)
                out.append((name, mapped[name]))
            elif name in self.unmapped:
                h = self.unmapped[name]
                out.append((name, LandmarkEstimate(h.point_fl, h.cov_fl)))
        return out

    def _predict(
        self,
        points: NDArray[np.float64],
        covs: NDArray[np.float64],
        origin: NDArray[np.float64],
        heading: float | NDArray[np.float64],
        pos_var: float,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return predict_bearings(
            origin,
            heading,
            points,
            covs,
            origin_var_fl=pos_var,
            bearing_var_rad=2.0 * self.sigma_rad**2,
        )

    def _outside(self, pred: NDArray[np.float64], std: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Predictions outside the camera's view by more than their gate."""
        return outside_view(pred, std, self.field_of_view_rad, n_std=math.sqrt(GATE_CHI2))

    def _class(
        self,
        label: str,
        dets: tuple[NDArray[np.float64], NDArray[np.float64]],
        origins: tuple[NDArray[np.float64], NDArray[np.float64]],
        heading: float,
        pos_var: float,
        mapped: Mapping[str, LandmarkEstimate],
        out: MovementAssociation,
    ) -> tuple[list[int], list[int]]:
        """Assign the class's detections to its named landmarks; the detections left free."""
        known = self._known(label, mapped)
        free: list[list[int]] = []
        for end in (0, 1):
            det = dets[end]
            where = "O1" if end == 0 else "O2"
            if not known:
                free.append(list(range(det.size)))
                continue
            pts = np.array([e.mean_fl for _, e in known])
            covs = np.array([e.cov_fl for _, e in known])
            pred, std = self._predict(pts, covs, origins[end], heading, pos_var)
            vague = std > MAX_PRED_STD_EPS * self.eps_rad
            for k in np.flatnonzero(vague):
                out.unresolved[f"{known[k][0]}@{where}"] = (
                    f"predicted bearing too uncertain to associate (std {_deg(float(std[k]))})"
                )
                out.outcomes.setdefault(known[k][0], []).append("vague")
            away = self._outside(pred, std)
            for k in np.flatnonzero(away & ~vague):
                out.not_visible[f"{known[k][0]}@{where}"] = (
                    f"predicted at {_deg(float(pred[k]))}, outside the camera's field of view"
                )
            sharp = np.flatnonzero(~vague & ~away)
            pred, std = pred[sharp], std[sharp]
            usable = [known[i] for i in sharp]
            range_fl, range_std_fl = self._ranges(usable, origins[end], pos_var, mapped)
            a = assign(
                pred,
                std,
                det,
                range_fl=range_fl,
                range_std_fl=range_std_fl,
                in_line_rad=self.eps_rad,
            )
            bmap = out.bearings_o1_rad if end == 0 else out.bearings_o2_rad
            for i, j in a.pairs:
                bmap[usable[i][0]] = float(det[j])
                out.names[label][end][j] = usable[i][0]
                out.outcomes.setdefault(usable[i][0], []).append("seen")
            for i in a.missing:
                out.not_visible[f"{usable[i][0]}@{where}"] = (
                    f"predicted at {_deg(float(pred[i]))}, not detected (hidden or out of range)"
                )
                out.outcomes.setdefault(usable[i][0], []).append("missed")
            for i, front in a.hidden:
                out.not_visible[f"{usable[i][0]}@{where}"] = (
                    f"predicted at {_deg(float(pred[i]))}, hidden behind {usable[front][0]}"
                )
                out.outcomes.setdefault(usable[i][0], []).append("hidden")
            for i in a.contested_landmarks:
                out.outcomes.setdefault(usable[i][0], []).append("contested")
            if a.contested_landmarks or a.contested_detections:
                out.unresolved[f"{label}@{where}"] = _contested_text(a, usable, det)
            # contested detections may still be a landmark not named yet: hypotheses may take them
            free.append(sorted(a.unexplained + a.contested_detections))
        return free[0], free[1]

    def _ranges(
        self,
        usable: Sequence[tuple[str, LandmarkEstimate]],
        origin_fl: NDArray[np.float64],
        pos_var: float,
        mapped: Mapping[str, LandmarkEstimate],
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Distances (n,) of named landmarks from ``origin_fl`` and their stds (FL), NaN for
        a name not trusted to hide others (not in the map, or not confirmed)."""
        range_fl, range_std_fl = predict_ranges(
            origin_fl,
            np.array([e.mean_fl for _, e in usable]),
            np.array([e.cov_fl for _, e in usable]),
            origin_var_fl=pos_var,
        )
        trusted = [
            n in mapped and n in self.support and self.support[n].confirmed for n, _ in usable
        ]
        return np.where(trusted, range_fl, np.nan), range_std_fl

    def _grow(
        self,
        label: str,
        dets: tuple[NDArray[np.float64], ...],
        free: list[list[int]],
        origins: tuple[NDArray[np.float64], NDArray[np.float64]],
        heading: float,
        index: int,
    ) -> list[list[int]]:
        """Add rays to hypotheses from free detections; count misses; drop stale ones.

        A hypothesis whose gate holds one detection gains its ray if the rays still meet (else
        it is neither seen nor missed); one whose gate holds several waits for a clearer view;
        one whose gate holds none counts a miss. Detections in any gate are not free for new
        hypotheses."""
        hyps = [h for h in self.hypotheses[label] if index - h.born <= MAX_AGE]
        used: list[set[int]] = [set(), set()]
        for end in (0, 1):
            cand = free[end]
            if not hyps:
                break
            pts = np.array([h.point_fl for h in hyps])
            covs = np.array([h.cov_fl for h in hyps])
            pred, std = self._predict(pts, covs, origins[end], heading, 0.0)
            d2 = (wrap_rad(dets[end][cand][None, :] - pred[:, None]) / std[:, None]) ** 2
            inside = d2 <= GATE_CHI2
            used[end].update(cand[j] for j in np.flatnonzero(inside.any(axis=0)))
            away = self._outside(pred, std)
            grown: list[Hypothesis] = []
            for i, h in enumerate(hyps):
                hits = np.flatnonzero(inside[i])
                if hits.size == 0 and away[i]:  # out of view: neither seen nor missed
                    grown.append(h)
                    continue
                if hits.size == 0:
                    h.misses += 1
                    if h.misses < MAX_MISSES:
                        grown.append(h)
                    continue
                if hits.size == 1:
                    j = cand[int(hits[0])]
                    ray = Ray.placed(index, end, j, float(dets[end][j]), origins[end], heading)
                    child = fit(label, [*h.rays, ray], self.eps_rad, self.sigma_rad, h.point_fl)
                    if child is not None:
                        child.misses, child.born = h.misses, h.born
                        grown.append(child)
                    else:  # in its gate but off its point: neither seen nor missed here
                        grown.append(h)
                else:
                    grown.append(h)  # several detections in its gate: wait for a clearer view
            grown.sort(key=lambda h: (-h.lines_of_sight(self._distinct), h.rms_rad))
            hyps = grown[:MAX_HYPOTHESES]
        self.hypotheses[label] = hyps
        return [[j for j in free[end] if j not in used[end]] for end in (0, 1)]

    def _birth(
        self,
        label: str,
        dets: tuple[NDArray[np.float64], ...],
        free: list[list[int]],
        origins: tuple[NDArray[np.float64], NDArray[np.float64]],
        heading: float,
        index: int,
    ) -> None:
        """One hypothesis per pairing of free detections at O1 and O2 whose rays meet."""
        for i in free[0]:
            r1 = Ray.placed(index, 0, i, float(dets[0][i]), origins[0], heading)
            for j in free[1]:
                r2 = Ray.placed(index, 1, j, float(dets[1][j]), origins[1], heading)
                if cannot_meet(r1, r2, self.eps_rad):
                    continue
                h = fit(label, [r1, r2], self.eps_rad, self.sigma_rad)
                if h is not None:
                    self.hypotheses[label].append(h)

    def _confirm(
        self, label: str, out: MovementAssociation, mapped: Mapping[str, LandmarkEstimate]
    ) -> None:
        """Name hypotheses seen often enough, within the class's catalog count; drop those
        that are a named landmark seen again (its detection fell outside its gate)."""
        named = self._known(label, mapped)
        estimates = [e for _, e in named]
        kept = [h for h in self.hypotheses[label] if not self._same(h, *estimates)]
        self.hypotheses[label] = kept
        lines = {id(h): h.lines_of_sight(self._distinct) for h in self.hypotheses[label]}
        ready = [
            h
            for h in self.hypotheses[label]
            if lines[id(h)] >= CONFIRM_POSITIONS and len(h.movements) >= CONFIRM_MOVEMENTS
        ]
        ready.sort(key=lambda h: (-lines[id(h)], h.rms_rad))
        taken: set[tuple[int, int, int]] = set()
        for h in ready:
            rivals = [
                o
                for o in self.hypotheses[label]
                if o is not h
                and o.keys & h.keys
                and _rivals(o, h, lines[id(o)], lines[id(h)])
                and not self._same(o, LandmarkEstimate(h.point_fl, h.cov_fl))
            ]  # one that fits its point is the same landmark with a ray more or less
            if h.keys & taken or rivals:
                continue  # its pairing is still disputed: wait for later movements
            taken |= h.keys
            self._give_name(label, h, lines[id(h)], out)
        self.hypotheses[label] = [h for h in self.hypotheses[label] if not h.keys & taken]

    def _give_name(
        self,
        label: str,
        h: Hypothesis,
        lines: int,
        out: MovementAssociation,
        *,
        searched: bool = False,
        retract: str | None = None,
        why: str | None = None,
    ) -> bool:
        """Name ``h`` (seen along ``lines`` lines of sight; ``searched``: found by the search
        among unnamed detections): the next free name of ``label``, or when the catalog is full
        ``retract`` (retracted for ``why``) or else the most doubtful one (False: none is
        doubtful; reported)."""
        if len(self.named[label]) < self.capacity[label]:
            name = slot_name(label, len(self.named[label]) + 1)
            self.named[label].append(name)
        else:
            weakest = retract or self._most_doubtful(label)
            if weakest is None:
                out.unresolved[f"{label} beyond catalog"] = (
                    f"a landmark of {label} fits {len(h.rays)} keyframes at "
                    f"({h.point_fl[0]:.2f}, {h.point_fl[1]:.2f}) FL but the catalog has "
                    f"{self.capacity[label]} of {label}, all named; not mapped"
                )
                return False
            name = weakest
            self._retract(label, name, h, lines, out, why)
        self.unmapped[name] = h
        self.support[name] = Support(out.index, searched=searched)
        if (young := self.support[name].unconfirmed()) is not None:
            out.unconfirmed[name] = young
        out.confirmed.append(name)
        out.history[name] = [(r.movement, r.end, r.bearing_rad) for r in h.rays]
        # its detections are no longer unnamed: the search must not give them a second name
        self._unnamed[label] = [u for u in self._unnamed[label] if u[:3] not in h.keys]
        for r in h.rays:
            if r.movement == out.index:
                out.names[label][r.end][r.detection] = name
        return True

    def _keep_unnamed(self, label: str, out: MovementAssociation) -> None:
        """Keep this movement's detections of ``label`` that no name took."""
        dets = self._dets[label]
        for end in (0, 1):
            for j, name in enumerate(out.names[label][end]):
                if name is None:
                    self._unnamed[label].append((out.index, end, j, float(dets[end][j])))

    def _discover(
        self, label: str, out: MovementAssociation, mapped: Mapping[str, LandmarkEstimate]
    ) -> None:
        """Name a landmark of ``label`` that the hypotheses did not (they kept disputing or
        swallowing its detections) but that the unnamed detections of the last
        :data:`DISCOVER_WINDOW` movements point at. The candidate points are the crossings of
        this movement's rays (:func:`_crossings`); the one most keyframes' rays pass near is
        fitted to them and named if it meets the ``DISCOVER_*`` thresholds and is not mostly
        a named landmark seen again. With the catalog full it takes the most doubtful name."""
        first = out.index - DISCOVER_WINDOW
        kept = [u for u in self._unnamed[label] if u[0] > first]
        self._unnamed[label] = kept
        full = len(self.named[label]) >= self.capacity[label]
        if full and self._most_doubtful(label) is None:
            return
        rays = [
            Ray.placed(m, e, j, b, pose.o2_fl if e else pose.o1_fl, pose.heading_rad)
            for m, e, j, b in kept
            if (pose := self._trajectory.get(m)) is not None
        ]
        if len(rays) < DISCOVER_KEYFRAMES:
            return
        rs = RaySet(rays)
        points = _crossings(rs, out.index, MIN_PARALLAX_EPS * self.eps_rad)
        if points.shape[0] == 0:
            return
        tol = FIT_TOL_EPS * self.eps_rad
        err = rs.errors(points)
        best = int(np.argmax(rs.keyframes_within(err, tol)))
        h: Hypothesis | None = None
        point = points[best]
        for _ in range(2):  # the crossing, then the point its rays fit, gathers the rays
            found = rs.nearest_per_keyframe(rs.errors(point[None, :])[0], tol)
            if len(found) < DISCOVER_KEYFRAMES:
                return
            h = fit(label, found, self.eps_rad, self.sigma_rad, point)
            if h is None:
                return
            point = h.point_fl
        assert h is not None
        lines = h.lines_of_sight(self._distinct)
        fan = lines == DISCOVER_LINES - 1 and len(h.rays) >= DISCOVER_FAN_KEYFRAMES
        if (lines < DISCOVER_LINES and not fan) or len(h.movements) < DISCOVER_MOVEMENTS:
            return
        for _, e in self._known(label, mapped):
            if 2 * sum(self._ray_fits(r, e) for r in h.rays) > len(h.rays):
                return  # mostly bearings of a named landmark: that one, seen again
        seen, predicted = self._predicted_seen(h, min(r.movement for r in h.rays))
        if seen < (DISCOVER_FAN_SEEN_SHARE if fan else DISCOVER_SEEN_SHARE) * predicted:
            return
        if self._give_name(label, h, lines, out, searched=True):
            self.hypotheses[label] = [o for o in self.hypotheses[label] if not o.keys & h.keys]

    def _predicted_seen(self, h: Hypothesis, since: int) -> tuple[int, int]:
        """At the placed keyframes from movement ``since`` on where the bearing of ``h``'s
        point is sharp enough to gate: how many held a detection of its class (named or not)
        in the gate, and how many there were."""
        keys = [(k, end) for (k, end) in self._seen_at if k >= since and k in self._trajectory]
        if not keys:
            return 0, 0
        poses = [self._trajectory[k] for k, _ in keys]
        origins = np.array(
            [p.o1_fl if e == 0 else p.o2_fl for p, (_, e) in zip(poses, keys, strict=True)]
        )
        n = len(keys)
        pred, std = self._predict(
            np.broadcast_to(h.point_fl, (n, 2)),
            np.broadcast_to(h.cov_fl, (n, 2, 2)),
            origins,
            np.array([p.heading_rad for p in poses]),
            0.0,
        )
        seen = predicted = 0
        away = self._outside(pred, std)
        for i, key in enumerate(keys):
            if std[i] > MAX_PRED_STD_EPS * self.eps_rad or away[i]:
                continue
            predicted += 1
            det = self._seen_at[key].get(h.label, np.zeros(0))
            seen += bool(np.any((wrap_rad(det - pred[i]) / std[i]) ** 2 <= GATE_CHI2))
        return seen, predicted

    def _most_doubtful(self, label: str) -> str | None:
        """The named landmark of ``label`` seen at the smallest share of its predictions among
        the doubtful ones (None: none is doubtful)."""
        doubtful = [
            (s.seen / max(s.predicted, 1), -s.predicted, n)
            for n in self.named[label]
            if (s := self.support[n]).doubt() is not None
        ]
        return min(doubtful)[2] if doubtful else None

    def _retract(
        self,
        label: str,
        name: str,
        h: Hypothesis,
        lines: int,
        out: MovementAssociation,
        why: str | None = None,
    ) -> None:
        """Take ``name`` from the landmark it was given to, a doubtful one (the estimator
        forgets it and every bearing given to it), and give it to ``h``, which the full catalog
        kept out (``why``: another reason, said instead)."""
        out.retracted[name] = why or (
            f"{self.support[name].doubt()}; retracted: the name goes to a landmark of {label} "
            f"seen along {lines} lines of sight at ({h.point_fl[0]:.2f}, {h.point_fl[1]:.2f}) "
            "FL, kept out while the catalog was full"
        )
        out.unresolved[f"{name} retracted"] = out.retracted[name]
        out.doubtful.pop(name, None)
        out.unresolved.pop(f"{name} doubtful", None)
        out.bearings_o1_rad.pop(name, None)
        out.bearings_o2_rad.pop(name, None)
        for end in (0, 1):
            out.names[label][end][:] = [None if n == name else n for n in out.names[label][end]]

    def _replace(self, trajectory: Mapping[int, MovementPose]) -> None:
        """Place the rays of hypotheses and unmapped named landmarks on ``trajectory``."""
        ends = {
            (k, end): ((float(o[0]), float(o[1])), p.heading_rad)
            for k, p in trajectory.items()
            for end, o in enumerate((p.o1_fl, p.o2_fl))
        }
        stays: dict[int, bool] = {}  # id(ray) -> whether its new placement is close to it

        def still(r: Ray) -> bool:
            if (known := stays.get(id(r))) is None:
                at = ends.get((r.movement, r.end))
                known = at is None or _close_to(r, at[0], at[1] + r.bearing_rad, self.sigma_rad)
                stays[id(r)] = known
            return known

        def moved(h: Hypothesis) -> Hypothesis | None:
            if all(still(r) for r in h.rays):
                return h
            rays = [_on(r, trajectory.get(r.movement)) for r in h.rays]
            refit = fit(h.label, rays, self.eps_rad, self.sigma_rad, h.point_fl)
            if refit is not None:
                refit.misses, refit.born = h.misses, h.born
            return refit

        for label, hyps in self.hypotheses.items():
            self.hypotheses[label] = [m for m in map(moved, hyps) if m is not None]
        for name, h in list(self.unmapped.items()):
            self.unmapped[name] = moved(h) or h

    def _ray_fits(self, r: Ray, e: LandmarkEstimate) -> bool:
        """Whether ray ``r`` is within the gate of the bearing of ``e`` predicted from its
        keyframe (first order, as :func:`~pipeline.association.predict.predict_bearings`, in
        scalars: a few rays and landmarks at a time)."""
        dx, dy = float(e.mean_fl[0]) - r.origin_fl[0], float(e.mean_fl[1]) - r.origin_fl[1]
        r2 = max(dx * dx + dy * dy, 1e-12)
        jx, jy = -dy / r2, dx / r2
        c = e.cov_fl
        var = jx * jx * c[0, 0] + 2 * jx * jy * c[0, 1] + jy * jy * c[1, 1] + 2 * self.sigma_rad**2
        err = math.remainder(math.atan2(dy, dx) - r.direction_rad, math.tau)
        return err * err <= GATE_CHI2 * float(var)

    def _same(self, h: Hypothesis, *named: LandmarkEstimate) -> bool:
        """Whether every ray of ``h`` is a bearing of one of ``named`` (within the gate of its
        predicted bearing from the ray's keyframe): then ``h`` is that landmark seen again."""
        if not any(self._ray_fits(h.rays[-1], e) for e in named):
            return False  # the last ray alone rules most of them out
        return any(all(self._ray_fits(r, e) for r in h.rays) for e in named)


def pose_between(o1_fl: NDArray[np.float64], o2_fl: NDArray[np.float64]) -> MovementPose:
    """The movement from O1 to O2 (each (2,), or particles (m, 2) whose mean is taken; FL)."""
    o1 = np.asarray(o1_fl, np.float64).reshape(-1, 2).mean(axis=0)
    o2 = np.asarray(o2_fl, np.float64).reshape(-1, 2).mean(axis=0)
    d = o2 - o1
    return MovementPose(o1, math.atan2(d[1], d[0]), max(float(np.hypot(*d)), 1e-6))


def _close_to(
    ray: Ray, origin_fl: tuple[float, float], direction_rad: float, sigma_rad: float
) -> bool:
    """Whether ``ray`` placed anew at ``origin_fl`` along ``direction_rad`` moves less than
    :data:`MOVED_FL` and turns less than a tenth of ``sigma_rad``."""
    return (
        math.dist(origin_fl, ray.origin_fl) < MOVED_FL
        and abs(direction_rad - ray.direction_rad) < 0.1 * sigma_rad
    )


def _on(ray: Ray, pose: MovementPose | None) -> Ray:
    """``ray`` from its keyframe as ``pose`` places it (unchanged when None)."""
    if pose is None:
        return ray
    o = pose.o1_fl if ray.end == 0 else pose.o2_fl
    return replace(
        ray, origin_fl=(float(o[0]), float(o[1])), direction_rad=pose.heading_rad + ray.bearing_rad
    )


def _all_detections(
    unique: Mapping[str, float],
    per_class: Mapping[str, Sequence[float]],
    known: set[str],
) -> dict[str, Sequence[float]]:
    """One keyframe's detections per class for matching: each identified bearing whose name is
    in ``known`` as a class of its own, then the detections of the shared classes."""
    return {**{n: [b] for n, b in unique.items() if n in known}, **per_class}


def _place_chained(
    s: Sightings, o1_fl: NDArray[np.float64], sigma_rad: float
) -> tuple[MovementPose, float] | None:
    """A movement that starts where the last one ended (the robot turns in place): heading
    from the bearings at O1, length from those at O2 (weighted least squares along the
    heading); None when the bearings at O2 do not fix the length."""
    at1, at2 = s.end == 0, s.end == 1
    d1 = s.points_fl[at1] - o1_fl
    ang = np.arctan2(d1[:, 1], d1[:, 0]) - s.bearings_rad[at1]
    heading = math.atan2(float(np.sin(ang).sum()), float(np.cos(ang).sum()))
    u = np.array([math.cos(heading), math.sin(heading)])
    p2 = s.points_fl[at2]
    dirs = heading + s.bearings_rad[at2]
    n = np.column_stack((-np.sin(dirs), np.cos(dirs)))
    w = 1.0 / np.maximum(((p2 - o1_fl) ** 2).sum(axis=1), 1e-9)
    nu = n @ u
    den = float((w * nu**2).sum())
    if den < 1e-6 * float(w.sum()):
        return None
    t = -float((w * nu * ((o1_fl - p2) * n).sum(axis=1)).sum()) / den
    if not t > 1e-3:
        return None
    pos_std = sigma_rad / math.sqrt(den)
    return MovementPose(np.asarray(o1_fl, np.float64), heading, t), pos_std


def _crossings(rs: RaySet, index: int, min_parallax_rad: float) -> NDArray[np.float64]:
    """Where each ray at O1 of movement ``index`` crosses each ray at its O2, ahead of both
    with at least ``min_parallax_rad`` between them: points (c, 2) FL."""
    a = np.flatnonzero(rs.frames == 2 * index)
    b = np.flatnonzero(rs.frames == 2 * index + 1)
    ua, ub = rs.units[a][:, None, :], rs.units[b][None, :, :]
    cross = ua[..., 0] * ub[..., 1] - ua[..., 1] * ub[..., 0]
    d = rs.origins_fl[b][None, :, :] - rs.origins_fl[a][:, None, :]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # parallel: no crossing
        t1 = (d[..., 0] * ub[..., 1] - d[..., 1] * ub[..., 0]) / cross
        t2 = (d[..., 0] * ua[..., 1] - d[..., 1] * ua[..., 0]) / cross
    parallax = np.abs(wrap_rad(rs.dirs_rad[a][:, None] - rs.dirs_rad[b][None, :]))
    ia, ib = np.nonzero((t1 > 0.0) & (t2 > 0.0) & (parallax >= min_parallax_rad))
    out: NDArray[np.float64] = rs.origins_fl[a][ia] + t1[ia, ib][:, None] * rs.units[a][ia]
    return out


def _rivals(o: Hypothesis, h: Hypothesis, po: int, ph: int) -> bool:
    """Whether ``o``, seen along ``po`` lines of sight, still disputes ``h``, seen along ``ph``
    (see :data:`RIVAL_LEAD`, :data:`RIVAL_RMS_RATIO`)."""
    if po + RIVAL_LEAD <= ph:
        return False
    return not (po <= ph and o.rms_rad >= RIVAL_RMS_RATIO * h.rms_rad)


def _contested_text(
    a: Assignment, known: list[tuple[str, LandmarkEstimate]], det: NDArray[np.float64]
) -> str:
    lms = ", ".join(known[i][0] for i in a.contested_landmarks) or "no landmark"
    bs = ", ".join(_deg(float(det[j])) for j in a.contested_detections) or "none"
    return (
        f"{lms}: several plausible detections or overlapping predictions (detections at {bs}); "
        "not used"
    )
