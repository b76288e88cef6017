"""Landmarks that look alike, movement by movement: association and its loop with the estimator.

:class:`AlikeLandmarks` (driven by the runner, ``replay/stages.py``) turns a movement's keyframe
detections into what the associator takes (bearings of landmarks with a class of their own,
blobs per shared class), gives the estimator the named landmarks' bearings, and after the
estimator has placed the movement lets the associator grow its hypotheses, makes the estimator
forget the landmarks whose names were taken back, and hands it the earlier bearings of landmarks
named now (:meth:`pipeline.joint.JointSlam.add_history`). Once the log is processed,
:meth:`final` associates every keyframe's detections again with the final map
(:func:`pipeline.association.final.associate_final`) and gives the names those bearings, in
turn with solving the map again, until the two agree.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace

from data_schemas.session import Session, shared_classes
from pipeline.association.final import FinalDetection, Status, weak_names
from pipeline.association.result import MovementAssociation
from pipeline.association.tracker import Associator
from pipeline.bearings import Detection, camera_view_rad
from pipeline.estimators import AssociatingEstimator
from pipeline.geometry import KeyframePose, MovementPose
from pipeline.slam import MovementObservation, MovementResult, MovementStatus

#: Keyframe poses of the final map, (movement, end) -> pose.
Poses = dict[tuple[int, int], KeyframePose]
#: Movements the map holds misplaced, as placed again by matching: movement -> pose (FL).
Moved = dict[int, MovementPose]
#: Once the log is processed, the map is repaired (a free name given, the least supported one
#: moved, names under suspicion given anew) and associated again at most this many times:
#: a name given frees the detections it explains, and those left may then point at another
#: landmark.
REPAIR_ROUNDS = 5
#: Once the log is processed, each name's bearings in the map are replaced by the detections the
#: final association gives it, the map is solved again and repaired, in rounds until neither
#: changes anything, at most this many rounds (association and estimation in turn).
RESOLVE_ROUNDS = 6
#: A name is given its final association's detections only when they are at least this many
#: (fewer may not place it; it keeps the bearings it was named and associated with).
RESOLVE_MIN_BEARINGS = 8
#: Once the final rounds end, a map that leaves more than this share of the shared classes'
#: detections at the keyframes it holds unnamed is built a
#: second time from the first movement with the final association's names
#: (:meth:`AlikeLandmarks.second_pass`), again from each map so built that explains more, at
#: most this many times.
SECOND_PASS_UNNAMED = 0.10
SECOND_PASSES = 3


class AlikeLandmarks:
    """Association for one run (see the module docstring); ``classes`` is label -> catalog names."""

    def __init__(self, session: Session) -> None:
        self.classes = shared_classes(session.landmarks)
        self.alike = {n for names in self.classes.values() for n in names}
        self.associator = Associator(
            {label: len(names) for label, names in self.classes.items()},
            session.reference,
            vision_error_rad=session.vision_error_rad,
            field_of_view_rad=camera_view_rad(session.calibration),
        )
        #: every keyframe's detections per shared class: (movement, end) -> label -> bearings
        self.keyframe_blobs: dict[tuple[int, int], dict[str, list[float]]] = {}
        #: ... and its bearings of landmarks of a class of their own: (movement, end) -> name ->
        #: bearing
        self.keyframe_unique: dict[tuple[int, int], dict[str, float]] = {}
        #: the bearings the estimator was given of each name: (movement, end, bearing_rad)
        self.given: dict[str, set[tuple[int, int, float]]] = {}
        #: each observed movement's commanded turn (rad) and driven distance (m), by index
        self.motion: dict[int, tuple[float | None, float | None]] = {}

    def landmarks(self, catalog: Sequence[str]) -> list[str]:
        """What the estimator maps: catalog landmarks of their own class, then ``red#k`` names."""
        return [n for n in catalog if n not in self.alike] + self.associator.names

    def observe(
        self,
        index: int,
        detections: tuple[Mapping[str, Detection], Mapping[str, Detection]],
        turn_rad: float | None,
        distance_m: float | None,
        estimator: AssociatingEstimator,
    ) -> tuple[MovementObservation, MovementAssociation]:
        """The movement's observation for the estimator, named landmarks included (its commanded
        turn and driven distance as given)."""
        unique = tuple(
            {
                n: d.bearing_rad
                for n, d in dets.items()
                if n not in self.alike and d.bearing_rad is not None
            }
            for dets in detections
        )
        blobs = tuple(
            {
                label: [b.bearing_rad for b in dets[names[0]].blobs]
                for label, names in self.classes.items()
            }
            for dets in detections
        )
        for end, per_class in enumerate(blobs):
            self.keyframe_blobs[index, end] = per_class
            self.keyframe_unique[index, end] = unique[end]
        self.motion[index] = (turn_rad, distance_m)
        assoc = self.associator.associate(
            index, (unique[0], unique[1]), (blobs[0], blobs[1]), estimator.marginals
        )
        for end, named in enumerate((assoc.bearings_o1_rad, assoc.bearings_o2_rad)):
            for name, b in named.items():
                self.given.setdefault(name, set()).add((index, end, b))
        obs = MovementObservation(
            index,
            {**unique[0], **assoc.bearings_o1_rad},
            {**unique[1], **assoc.bearings_o2_rad},
            turn_rad,
            distance_m,
        )
        return obs, assoc

    def after(
        self, assoc: MovementAssociation, result: MovementResult, estimator: AssociatingEstimator
    ) -> None:
        """Grow the hypotheses with the movement as the estimator placed it; name confirmed ones."""
        trajectory = estimator.movement_poses()
        pose = trajectory.get(result.index) if result.status == MovementStatus.OK else None
        self.associator.hypothesize(
            assoc, pose, estimator.marginals, trajectory, estimator.bearing_scatter
        )
        self._give(assoc.retracted, assoc.history, estimator)

    def _give(
        self,
        forgotten: Iterable[str],
        history: Mapping[str, Sequence[tuple[int, int, float]]],
        estimator: AssociatingEstimator,
    ) -> None:
        """The estimator forgets the ``forgotten`` names and takes ``history`` as bearings."""
        for name in forgotten:
            estimator.forget(name)
            self.given.pop(name, None)
        for name, bearings in history.items():
            estimator.add_history(name, bearings)
            self.given.setdefault(name, set()).update(bearings)

    def final(self, estimator: AssociatingEstimator) -> FinalAssociation:
        """Every keyframe's detections associated with ``estimator``'s final map and what it
        leaves open per class, association and map made to agree: in turn, each name's
        bearings in the map become its detections with the final map and the map is solved
        again (:meth:`pipeline.joint.JointSlam.rebear`), and when the unexplained detections
        point at a landmark, a free name of its class is given to it, or with every name given
        the one the final map supports least is moved there, or names under suspicion are
        given anew where their detections and those meet
        (:meth:`pipeline.association.Associator.repair_final`; the estimator settles,
        :meth:`pipeline.joint.JointSlam.settle`); each followed by the association made again,
        until neither changes anything (at most :data:`RESOLVE_ROUNDS` rounds,
        :data:`REPAIR_ROUNDS` repairs)."""

        def noise_rad() -> float | None:
            """The map's bearing noise std as it stands (None: not estimated)."""
            noise = estimator.noise
            return None if noise is None else noise.sigma_rad

        def associate() -> tuple[list[FinalDetection], dict[str, str], Poses, list[int], Moved]:
            """The final association: its detections, reports and keyframes, the movements
            placed by matching, and those of them the map holds misplaced (as placed)."""
            poses: Poses = estimator.keyframe_poses()
            sigma = noise_rad()
            left_out, wrong = self.associator.place_left_out(
                self.keyframe_unique, self.keyframe_blobs, poses, estimator.marginals, sigma
            )
            poses = {key: pose for key, pose in poses.items() if key[0] not in wrong}
            poses.update(left_out)
            found, reports = self.associator.associate_final(
                self.keyframe_blobs, poses, estimator.marginals, sigma
            )
            placed = sorted({m for m, _ in left_out})
            moved = {
                m: MovementPose.from_ends(
                    left_out[m, 0].origin_fl, left_out[m, 0].heading_rad, left_out[m, 1].origin_fl
                )
                for m in wrong
                if (m, 0) in left_out and (m, 1) in left_out
            }
            return found, reports, poses, placed, moved

        detections, reports, poses, placed, moved = associate()
        last = max((m for m, _ in self.keyframe_blobs), default=-1)
        retracted: dict[str, str] = {}
        named_at_end: dict[str, str] = {}
        repairs = 0
        for _ in range(RESOLVE_ROUNDS):
            anew = self._reassigned(detections, set(placed) - set(moved))
            if anew or moved:  # each name's bearings: its detections with the final map
                estimator.rebear(anew, moved)  # solved again, misplaced movements as matched
                for name, rays in anew.items():
                    self.given[name] = set(rays)
                detections, reports, poses, placed, moved = associate()
            repair = None
            if repairs < REPAIR_ROUNDS:
                repair = self.associator.repair_final(
                    detections, poses, estimator.marginals, last, noise_rad()
                )
            if repair is not None:
                repairs += 1
                self._give(repair.retracted, repair.history, estimator)
                estimator.settle()
                retracted.update(repair.retracted)
                named_at_end.update(repair.named_at_end)
                detections, reports, poses, placed, moved = associate()
            elif not anew:
                break
        sigma = noise_rad()
        weak = weak_names(
            detections,
            poses,
            estimator.marginals,
            [n for names in self.associator.named.values() for n in names],
            noise_rad=self.associator.model.sigma_rad if sigma is None else sigma,
            eps_rad=self.associator.model.eps_rad,
        )
        return FinalAssociation(detections, reports, retracted, placed, named_at_end, weak)

    def rebuilt(
        self,
        first: FinalAssociation,
        fresh: Callable[[], AssociatingEstimator],
    ) -> tuple[AlikeLandmarks, AssociatingEstimator, FinalAssociation] | None:
        """The map built again from the first movement (:meth:`second_pass`) while it stays
        broken and each pass explains more detections, at most :data:`SECOND_PASSES` times:
        the last association, estimator and final association, or None when no pass
        explained more than ``first``."""
        best = None
        alike, final = self, first
        for _ in range(SECOND_PASSES):
            again = alike.second_pass(final, fresh)
            if again is None:
                break
            best = again
            alike, _, final = again
        return best

    def second_pass(
        self,
        first: FinalAssociation,
        fresh: Callable[[], AssociatingEstimator],
    ) -> tuple[AlikeLandmarks, AssociatingEstimator, FinalAssociation] | None:
        """The map built a second time when ``first`` (:meth:`final`'s result) leaves it
        broken by its own evidence (:meth:`FinalAssociation.broken`): a ``fresh`` estimator
        takes every movement again from the first, each keyframe's detections under the names
        ``first`` gave them (no name made of mixed rays enters early to misplace the
        keyframes), then :meth:`final` on a copy of this association. Returns the copy, the new
        estimator and its final association when that explains more detections than ``first``
        (:meth:`FinalAssociation.explained`), else None (keep the first map)."""
        if not first.broken():
            return None
        named: dict[tuple[int, int], dict[str, float]] = {}
        for d in first.detections:
            if d.name is not None and d.status == Status.NAMED:
                named.setdefault((d.movement, d.end), {})[d.name] = d.bearing_rad
        again = copy.deepcopy(self)
        again.given = {}
        estimator = fresh()
        for index in sorted(self.motion):
            ends = tuple(
                {**self.keyframe_unique.get((index, end), {}), **named.get((index, end), {})}
                for end in (0, 1)
            )
            for end, bearings in enumerate(ends):
                for name, b in bearings.items():
                    if name in self.alike:
                        again.given.setdefault(name, set()).add((index, end, b))
            estimator.process_movement(
                MovementObservation(index, ends[0], ends[1], *self.motion[index])
            )
        second = again.final(estimator)
        if second.explained() <= first.explained():
            return None
        # the names moved from where the run left them in either pass
        return (
            again,
            estimator,
            replace(
                second,
                retracted={**first.retracted, **second.retracted},
                named_at_end={**first.named_at_end, **second.named_at_end},
            ),
        )

    def _reassigned(
        self, detections: Sequence[FinalDetection], left_out: set[int]
    ) -> dict[str, list[tuple[int, int, float]]]:
        """The names whose detections with the final map (at keyframes the map holds, at least
        :data:`RESOLVE_MIN_BEARINGS`) are not the bearings the estimator was given: name ->
        those detections ``(movement, end, bearing_rad)``."""
        found: dict[str, list[tuple[int, int, float]]] = {}
        for d in detections:
            if d.name is not None and d.status == Status.NAMED and d.movement not in left_out:
                found.setdefault(d.name, []).append((d.movement, d.end, d.bearing_rad))
        return {
            name: rays
            for name, rays in found.items()
            if len(rays) >= RESOLVE_MIN_BEARINGS and set(rays) != self.given.get(name, set())
        }


@dataclass(frozen=True)
class FinalAssociation:
    """What :meth:`AlikeLandmarks.final` found: every keyframe detection with the final map,
    the reports per class, the names retracted and given anew once the log was processed
    (name -> why; the map changed only then), the movements the map left out or held
    misplaced that were placed by matching for this association, the free names given then to
    landmarks the unexplained detections point at (name -> why; the map changed then too), and
    the names the final association supports weakly (name -> why;
    :func:`pipeline.association.final.weak_names`)."""

    detections: list[FinalDetection]
    reports: dict[str, str]
    retracted: dict[str, str] = field(default_factory=dict)
    placed_by_matching: list[int] = field(default_factory=list)
    named_at_end: dict[str, str] = field(default_factory=dict)
    weak: dict[str, str] = field(default_factory=dict)

    def explained(self) -> int:
        """How many detections the final map gives a name."""
        return sum(1 for d in self.detections if d.status == Status.NAMED)

    def broken(self) -> bool:
        """Whether the map is broken by its own evidence: more than
        :data:`SECOND_PASS_UNNAMED` of the detections at the keyframes it holds left without a
        name."""
        held = [d for d in self.detections if d.status != Status.NOT_PLACED]
        unnamed = sum(1 for d in held if d.status != Status.NAMED)
        return unnamed > SECOND_PASS_UNNAMED * len(held)
