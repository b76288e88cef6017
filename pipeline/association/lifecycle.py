"""Hypotheses of each shared class, from birth to a name: where a look-alike landmark is named.

After a movement's assignment (:class:`pipeline.association.assign.MovementAssignment`),
:meth:`Lifecycle.step` takes the detections no named landmark explained, or that the
assignment left contested:

1. Growth: a hypothesis whose gate holds one detection gains that ray (if the rays still
   meet); one with none counts a miss. Rays kept from earlier movements are placed anew on
   the estimator's current trajectory.
2. Birth: pairs of detections still unexplained, one from each keyframe, whose rays meet ahead
   of both start new hypotheses (every pairing the two cones allow).
3. Confirmation: a hypothesis seen along four distinct lines of sight over two movements, every
   ray within eps of its point, is confirmed unless a rival sharing one of its rays still
   disputes it, and given a name (:meth:`Lifecycle.give_name`): ``label#k`` (k in order of
   confirmation) while the class has fewer named landmarks than the catalog has; hypotheses
   sharing a ray with it are dropped. A hypothesis whose every ray is a bearing of a named
   landmark is that landmark seen again (dropped). A hypothesis that misses :data:`MAX_MISSES`
   keyframes, or is not confirmed within :data:`MAX_AGE` movements, is dropped.
4. Discovery: the detections no name took are kept for :data:`DISCOVER_WINDOW` movements; when
   the rays of many of them, from many keyframes, pass near one point (a landmark whose rays
   the hypotheses kept disputing or swallowing, or one seen only from a narrow fan of
   directions, along too few lines of sight for a hypothesis), that point is named too.
5. Support: what became of each named landmark's predictions since it was named is counted
   (:meth:`Lifecycle.weigh`, :mod:`pipeline.association.support`); a name seen too rarely, or
   whose bearings in the joint map scatter too widely about it, is reported doubtful every
   movement while it stays so, a name not seen often enough since its naming to tell as
   unconfirmed. When the class's catalog is full and a hypothesis is confirmed, the most
   doubtful name is retracted and given to it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad
from pipeline.association.assign import Detections, MovementAssignment
from pipeline.association.hypotheses import (
    FIT_TOL_EPS,
    MIN_PARALLAX_EPS,
    Hypothesis,
    Ray,
    RaySet,
    cannot_meet,
    crossings,
    fit,
    ray_fits,
)
from pipeline.association.predict import GATE_CHI2, BearingModel
from pipeline.association.result import MovementAssociation, slot_name
from pipeline.association.support import Support
from pipeline.estimate import LandmarkEstimate
from pipeline.geometry import MovementPose

#: A hypothesis missing from this many keyframes where it was predicted is dropped.
MAX_MISSES = 2
#: ... as is one not confirmed within this many movements of its birth.
MAX_AGE = 8
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
#: A hypothesis sharing a ray with another is confirmed only when seen along this many more
#: lines of sight than it.
RIVAL_LEAD = 2
#: ... or from as many, with an RMS ray error this many times smaller.
RIVAL_RMS_RATIO = 2.0


class Lifecycle:
    """The hypotheses of each shared class and the names given (see the module docstring).

    Parameters
    ----------
    capacity : mapping label -> int
        Each shared class and how many catalog landmarks have it (the most that may be named).
    model : BearingModel
        The bearing error bound, its noise and the camera's view.

    Attributes
    ----------
    named : dict label -> list of str
        The names given in each class, in order.
    hypotheses : dict label -> list of Hypothesis
        The live hypotheses of each class.
    unmapped : dict name -> Hypothesis
        Named landmarks the estimator has not mapped yet: their rays, refitted as they grow.
    support : dict name -> Support
        What became of each named landmark's predictions since it was named.
    """

    def __init__(self, capacity: Mapping[str, int], model: BearingModel) -> None:
        self.capacity = dict(capacity)
        self.model = model
        self.named: dict[str, list[str]] = {c: [] for c in self.capacity}
        self.hypotheses: dict[str, list[Hypothesis]] = {c: [] for c in self.capacity}
        self.unmapped: dict[str, Hypothesis] = {}
        self.support: dict[str, Support] = {}
        #: every detection of each shared class at each keyframe (movement, end) so far
        self._seen_at: dict[tuple[int, int], dict[str, NDArray[np.float64]]] = {}
        #: per class, detections no name took: (movement, end, detection, bearing_rad)
        self._unnamed: dict[str, list[tuple[int, int, int, float]]] = {c: [] for c in self.capacity}
        #: the estimator's placement of each movement (index -> pose), as of the last one
        self._trajectory: dict[int, MovementPose] = {}
        self.distinct_rad = DISTINCT_EPS * model.eps_rad

    def known(
        self, label: str, mapped: Mapping[str, LandmarkEstimate]
    ) -> list[tuple[str, LandmarkEstimate]]:
        """The named landmarks of ``label`` with their estimates (FL): the map's, else their
        hypothesis's while the estimator has not mapped them (a name now in the map stops
        being kept as unmapped)."""
        out = []
        for name in self.named[label]:
            if name in mapped:
                self.unmapped.pop(name, None)
                out.append((name, mapped[name]))
            elif name in self.unmapped:
                h = self.unmapped[name]
                out.append((name, LandmarkEstimate(h.point_fl, h.cov_fl)))
        return out

    def trusted(self, mapped: Mapping[str, LandmarkEstimate]) -> set[str]:
        """Names trusted to hide others: in the map and confirmed."""
        return {n for n, s in self.support.items() if n in mapped and s.confirmed}

    # ------------------------------------------------------------------ support
    def weigh(self, out: MovementAssociation) -> None:
        """Count the outcomes of this movement's predictions; report doubtful and unconfirmed
        names."""
        for name, outcomes in out.outcomes.items():
            support = self.support.get(name)
            if support is not None and support.named_at < out.index:
                for outcome in outcomes:
                    support.add(outcome)
        self.report(out)

    def report(self, out: MovementAssociation) -> None:
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

    def most_doubtful(self, label: str) -> str | None:
        """The named landmark of ``label`` seen at the smallest share of its predictions among
        the doubtful ones (None: none is doubtful)."""
        doubtful = [
            (s.seen / max(s.predicted, 1), -s.predicted, n)
            for n in self.named[label]
            if (s := self.support[n]).doubt() is not None
        ]
        return min(doubtful)[2] if doubtful else None

    # ------------------------------------------------------------------ one movement
    def step(
        self,
        record: MovementAssignment,
        out: MovementAssociation,
        pose: MovementPose | None,
        mapped: Mapping[str, LandmarkEstimate],
        trajectory: Mapping[int, MovementPose] | None = None,
        scatter: Mapping[str, tuple[int, float]] | None = None,
    ) -> None:
        """Grow, start, confirm and drop hypotheses with the detections of ``record`` no name
        took; search the unnamed detections of the last movements for a landmark they missed.

        ``out`` is what association did for the movement (names given now are added to it),
        ``pose`` the movement as placed (None: not placed; nothing grows), ``mapped`` the
        estimator's map after it, ``trajectory`` the estimator's current placement of earlier
        movements (index -> pose): rays kept from them are placed anew. ``scatter`` is how
        widely each mapped name's bearings scatter about it (a name that scatters too widely
        is doubtful). The doubtful and unconfirmed names are reported anew in ``out``.
        """
        for end in (0, 1):
            self._seen_at[record.index, end] = {c: d[end] for c, d in record.detections_rad.items()}
        for named, support in self.support.items():
            support.scatter = (scatter or {}).get(named)
        if pose is None:
            self.report(out)
            return
        if trajectory:
            self._replace(trajectory)
            self._trajectory = dict(trajectory)
        self._trajectory[out.index] = pose
        for key in [k for k in self._seen_at if k[0] <= out.index - DISCOVER_WINDOW]:
            del self._seen_at[key]  # older than any ray the search keeps
        origins = (pose.o1_fl, pose.o2_fl)
        index = out.index
        for c, dets in record.detections_rad.items():
            for end in (0, 1):
                for j, name in enumerate(out.names[c][end]):
                    if name is not None and name in self.unmapped:
                        ray = Ray.placed(
                            index, end, j, float(dets[end][j]), origins[end], pose.heading_rad
                        )
                        self.unmapped[name].rays.append(ray)
            for name in self.named[c]:
                h = self.unmapped.get(name)
                refit = h and fit(c, h.rays, self.model.eps_rad, self.model.sigma_rad)
                if refit:
                    self.unmapped[name] = refit
            free = [list(f) for f in record.free(c)]
            if not self.hypotheses[c] and not free[0] and not free[1]:
                continue
            free = self._grow(c, dets, free, origins, pose.heading_rad, index)
            self._birth(c, dets, free, origins, pose.heading_rad, index)
            self._confirm(c, out, mapped)
            self._keep_unnamed(c, dets, out)
            self._discover(c, out, mapped)
            left = [f"{len(f)} at {w}" for f, w in zip(free, ("O1", "O2"), strict=True) if f]
            if left:
                out.unresolved.setdefault(
                    f"{c} unexplained",
                    f"{', '.join(left)} detection(s) of {c} explained by no named landmark "
                    f"({len(self.hypotheses[c])} hypothesis(es) of {c} open)",
                )
        out.n_hypotheses = self.count()
        self.report(out)

    def count(self) -> int:
        """Live hypotheses, every class."""
        return sum(len(h) for h in self.hypotheses.values())

    def _grow(
        self,
        label: str,
        dets: Detections,
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
        eps, sigma = self.model.eps_rad, self.model.sigma_rad
        hyps = [h for h in self.hypotheses[label] if index - h.born <= MAX_AGE]
        used: list[set[int]] = [set(), set()]
        for end in (0, 1):
            cand = free[end]
            if not hyps:
                break
            pts = np.array([h.point_fl for h in hyps])
            covs = np.array([h.cov_fl for h in hyps])
            pred, std = self.model.predict(pts, covs, origins[end], heading, 0.0)
            d2 = (wrap_rad(dets[end][cand][None, :] - pred[:, None]) / std[:, None]) ** 2
            inside = d2 <= GATE_CHI2
            used[end].update(cand[j] for j in np.flatnonzero(inside.any(axis=0)))
            away = self.model.outside(pred, std)
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
                    child = fit(label, [*h.rays, ray], eps, sigma, h.point_fl)
                    if child is not None:
                        child.misses, child.born = h.misses, h.born
                        grown.append(child)
                    else:  # in its gate but off its point: neither seen nor missed here
                        grown.append(h)
                else:
                    grown.append(h)  # several detections in its gate: wait for a clearer view
            grown.sort(key=lambda h: (-h.lines_of_sight(self.distinct_rad), h.rms_rad))
            hyps = grown[:MAX_HYPOTHESES]
        self.hypotheses[label] = hyps
        return [[j for j in free[end] if j not in used[end]] for end in (0, 1)]

    def _birth(
        self,
        label: str,
        dets: Detections,
        free: list[list[int]],
        origins: tuple[NDArray[np.float64], NDArray[np.float64]],
        heading: float,
        index: int,
    ) -> None:
        """One hypothesis per pairing of free detections at O1 and O2 whose rays meet."""
        eps, sigma = self.model.eps_rad, self.model.sigma_rad
        for i in free[0]:
            r1 = Ray.placed(index, 0, i, float(dets[0][i]), origins[0], heading)
            for j in free[1]:
                r2 = Ray.placed(index, 1, j, float(dets[1][j]), origins[1], heading)
                if cannot_meet(r1, r2, eps):
                    continue
                h = fit(label, [r1, r2], eps, sigma)
                if h is not None:
                    self.hypotheses[label].append(h)

    def _confirm(
        self, label: str, out: MovementAssociation, mapped: Mapping[str, LandmarkEstimate]
    ) -> None:
        """Name hypotheses seen often enough, within the class's catalog count; drop those
        that are a named landmark seen again (its detection fell outside its gate)."""
        named = self.known(label, mapped)
        estimates = [e for _, e in named]
        kept = [h for h in self.hypotheses[label] if not self._same(h, *estimates)]
        self.hypotheses[label] = kept
        lines = {id(h): h.lines_of_sight(self.distinct_rad) for h in self.hypotheses[label]}
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
            self.give_name(label, h, lines[id(h)], out)
        self.hypotheses[label] = [h for h in self.hypotheses[label] if not h.keys & taken]

    def give_name(
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
        doubtful; reported). The name, its rays (``history``) and its detections of this
        movement go into ``out``."""
        if len(self.named[label]) < self.capacity[label]:
            name = slot_name(label, len(self.named[label]) + 1)
            self.named[label].append(name)
        else:
            weakest = retract or self.most_doubtful(label)
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

    def _keep_unnamed(self, label: str, dets: Detections, out: MovementAssociation) -> None:
        """Keep this movement's detections ``dets`` of ``label`` that no name took."""
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
        this movement's rays (:func:`~pipeline.association.hypotheses.crossings`); the one most
        keyframes' rays pass near is fitted to them and named if it meets the ``DISCOVER_*``
        thresholds and is not mostly a named landmark seen again. With the catalog full it
        takes the most doubtful name."""
        eps, sigma = self.model.eps_rad, self.model.sigma_rad
        first = out.index - DISCOVER_WINDOW
        kept = [u for u in self._unnamed[label] if u[0] > first]
        self._unnamed[label] = kept
        full = len(self.named[label]) >= self.capacity[label]
        if full and self.most_doubtful(label) is None:
            return
        rays = [
            Ray.placed(m, e, j, b, pose.o2_fl if e else pose.o1_fl, pose.heading_rad)
            for m, e, j, b in kept
            if (pose := self._trajectory.get(m)) is not None
        ]
        if len(rays) < DISCOVER_KEYFRAMES:
            return
        rs = RaySet(rays)
        points = crossings(rs, out.index, MIN_PARALLAX_EPS * eps)
        if points.shape[0] == 0:
            return
        tol = FIT_TOL_EPS * eps
        err = rs.errors(points)
        best = int(np.argmax(rs.keyframes_within(err, tol)))
        h: Hypothesis | None = None
        point = points[best]
        for _ in range(2):  # the crossing, then the point its rays fit, gathers the rays
            found = rs.nearest_per_keyframe(rs.errors(point[None, :])[0], tol)
            if len(found) < DISCOVER_KEYFRAMES:
                return
            h = fit(label, found, eps, sigma, point)
            if h is None:
                return
            point = h.point_fl
        assert h is not None
        lines = h.lines_of_sight(self.distinct_rad)
        fan = lines == DISCOVER_LINES - 1 and len(h.rays) >= DISCOVER_FAN_KEYFRAMES
        if (lines < DISCOVER_LINES and not fan) or len(h.movements) < DISCOVER_MOVEMENTS:
            return
        for _, e in self.known(label, mapped):
            if 2 * sum(ray_fits(r, e, sigma) for r in h.rays) > len(h.rays):
                return  # mostly bearings of a named landmark: that one, seen again
        seen, predicted = self._predicted_seen(h, min(r.movement for r in h.rays))
        if seen < (DISCOVER_FAN_SEEN_SHARE if fan else DISCOVER_SEEN_SHARE) * predicted:
            return
        if self.give_name(label, h, lines, out, searched=True):
            self.hypotheses[label] = [o for o in self.hypotheses[label] if not o.keys & h.keys]

    def _predicted_seen(self, h: Hypothesis, since: int) -> tuple[int, int]:
        """:func:`seen_in_gate` at the placed keyframes from movement ``since`` on, each
        keyframe's detections of ``h``'s class named or not."""
        keys = [(k, end) for (k, end) in self._seen_at if k >= since and k in self._trajectory]
        poses = [self._trajectory[k] for k, _ in keys]
        origins = np.array(
            [p.o1_fl if e == 0 else p.o2_fl for p, (_, e) in zip(poses, keys, strict=True)]
        ).reshape(-1, 2)
        headings = np.array([p.heading_rad for p in poses])
        empty = np.zeros(0)
        bearings = [self._seen_at[key].get(h.label, empty) for key in keys]
        return seen_in_gate(h, origins, headings, bearings, self.model)

    def _replace(self, trajectory: Mapping[int, MovementPose]) -> None:
        """Place the rays of hypotheses and unmapped named landmarks on ``trajectory``."""
        ends = {
            (k, end): ((float(o[0]), float(o[1])), p.heading_rad)
            for k, p in trajectory.items()
            for end, o in enumerate((p.o1_fl, p.o2_fl))
        }
        stays: dict[int, bool] = {}  # id(ray) -> whether its new placement is close to it
        sigma = self.model.sigma_rad

        def still(r: Ray) -> bool:
            if (known := stays.get(id(r))) is None:
                at = ends.get((r.movement, r.end))
                known = at is None or _close_to(r, at[0], at[1] + r.bearing_rad, sigma)
                stays[id(r)] = known
            return known

        def moved(h: Hypothesis) -> Hypothesis | None:
            if all(still(r) for r in h.rays):
                return h
            rays = [_on(r, trajectory.get(r.movement)) for r in h.rays]
            refit = fit(h.label, rays, self.model.eps_rad, sigma, h.point_fl)
            if refit is not None:
                refit.misses, refit.born = h.misses, h.born
            return refit

        for label, hyps in self.hypotheses.items():
            self.hypotheses[label] = [m for m in map(moved, hyps) if m is not None]
        for name, h in list(self.unmapped.items()):
            self.unmapped[name] = moved(h) or h

    def _same(self, h: Hypothesis, *named: LandmarkEstimate) -> bool:
        """Whether every ray of ``h`` is a bearing of one of ``named`` (within the gate of its
        predicted bearing from the ray's keyframe): then ``h`` is that landmark seen again."""
        sigma = self.model.sigma_rad
        if not any(ray_fits(h.rays[-1], e, sigma) for e in named):
            return False  # the last ray alone rules most of them out
        return any(all(ray_fits(r, e, sigma) for r in h.rays) for e in named)


def seen_in_gate(
    h: Hypothesis,
    origins_fl: NDArray[np.float64],
    headings_rad: NDArray[np.float64],
    bearings_rad: list[NDArray[np.float64]],
    model: BearingModel,
) -> tuple[int, int]:
    """At how many keyframes ``h``'s point is predicted sharply enough to gate and in view,
    and at how many of those a detection of its class lay in the gate: (seen, predicted).

    Parameters
    ----------
    h : Hypothesis
        The point (FL) and its covariance.
    origins_fl : (n, 2) float
        The keyframes' positions, FL.
    headings_rad : (n,) float
        Their headings, rad, FL.
    bearings_rad : list of n (k_i,) float arrays
        Each keyframe's detections of ``h``'s class, rad, robot frame.
    model : BearingModel
        The prediction's noise and the camera's view.
    """
    n = len(bearings_rad)
    if n == 0:
        return 0, 0
    pred, std = model.predict(
        np.broadcast_to(h.point_fl, (n, 2)),
        np.broadcast_to(h.cov_fl, (n, 2, 2)),
        origins_fl,
        headings_rad,
        0.0,
    )
    usable = ~model.vague(std) & ~model.outside(pred, std)
    seen = sum(
        bool(np.any((wrap_rad(det - pred[i]) / std[i]) ** 2 <= GATE_CHI2))
        for i, det in enumerate(bearings_rad)
        if usable[i]
    )
    return seen, int(usable.sum())


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


def _rivals(o: Hypothesis, h: Hypothesis, po: int, ph: int) -> bool:
    """Whether ``o``, seen along ``po`` lines of sight, still disputes ``h``, seen along ``ph``
    (see :data:`RIVAL_LEAD`, :data:`RIVAL_RMS_RATIO`)."""
    if po + RIVAL_LEAD <= ph:
        return False
    return not (po <= ph and o.rms_rad >= RIVAL_RMS_RATIO * h.rms_rad)
