"""Per-movement association of landmarks that look alike: the associator that composes the steps.

For each movement (its two keyframes, O1 and O2), :meth:`Associator.associate`:

1. Places the movement from the bearings of landmarks whose class is their own (the reference
   pair included) and their map estimates
   (:func:`pipeline.association.match.place_movement`); when these are too few after a placed
   movement, by matching every detection with the map
   (:func:`pipeline.association.match.match_movement`).
2. Per shared class, predicts the bearing of each landmark already named (``red#1``, ...) from
   O1 and O2, with its std from the map covariance, the placement and the bearing noise
   (:func:`pipeline.association.predict.predict_named`), and assigns the class's detections
   (:func:`pipeline.association.assign.assign_movement`). Names in the map and confirmed
   (:attr:`pipeline.association.support.Support.confirmed`) also give their distances: of
   several predicted in line (within eps) on one blob, the one clearly in front takes it and
   hides the others. With the named landmarks' bearings the movement is placed again and
   assigned again.

Once the estimator has placed the movement, :meth:`Associator.hypothesize` hands the
assignment's record (:class:`pipeline.association.assign.MovementAssignment`, in
:attr:`MovementAssociation.assignment`) to the hypotheses
(:class:`pipeline.association.lifecycle.Lifecycle`): they grow, are born, confirmed and named
there, and the search among unnamed detections names what they missed.

Whatever is left unresolved (contested detections, unexplained detections, a class beyond its
catalog count, a movement that cannot be placed, a doubtful name) is reported in the movement's
result.

Once the log is processed, :meth:`Associator.place_left_out` places the movements the map
left out by matching, :meth:`Associator.associate_final` associates every keyframe's
detections again with the final map, and :meth:`Associator.repair_final` gives a name to a
landmark the detections it leaves unexplained point at (:mod:`pipeline.association.final`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from pipeline.association.assign import Detections, MovementAssignment, assign_movement
from pipeline.association.final import (
    FinalDetection,
    associate_final,
    missing_reports,
    repair_final,
)
from pipeline.association.hypotheses import Hypothesis
from pipeline.association.lifecycle import Lifecycle
from pipeline.association.match import (
    Matched,
    all_detections,
    match_movement,
    matching_map,
    misplaced,
    place_left_out,
    place_movement,
)
from pipeline.association.predict import BearingModel, Predicted, predict_named
from pipeline.association.result import MovementAssociation, slot_name
from pipeline.association.support import Support
from pipeline.estimate import LandmarkEstimate
from pipeline.geometry import KeyframePose, MovementPose

#: Once the log is processed, a keyframe the map holds is misplaced when a landmark of a class of
#: its own is seen more than this many eps from where the map puts it: the bound beyond which the
#: map takes a bearing for a wrong detection (``pipeline.joint.robustness.REJECT_EPS``; a test
#: holds them equal: association does not import the joint map's GTSAM code), here of a landmark
#: no other can be taken for.
MISPLACED_EPS = 2.0


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
        self.model = BearingModel(float(vision_error_rad), field_of_view_rad)
        self.capacity = dict(classes)
        self.reference = reference
        self.lifecycle = Lifecycle(self.capacity, self.model)
        #: the last movement placed and its pose (a movement after it is chained on it)
        self._last: tuple[int, MovementPose] | None = None

    @property
    def names(self) -> list[str]:
        """Every name a landmark of a shared class may get, class by class (``red#1`` ...)."""
        return [slot_name(c, k + 1) for c, n in self.capacity.items() for k in range(n)]

    @property
    def named(self) -> dict[str, list[str]]:
        """The names given in each class (:attr:`Lifecycle.named`)."""
        return self.lifecycle.named

    @property
    def support(self) -> dict[str, Support]:
        """What became of each named landmark's predictions (:attr:`Lifecycle.support`)."""
        return self.lifecycle.support

    @property
    def unmapped(self) -> dict[str, Hypothesis]:
        """Named landmarks not in the map yet (:attr:`Lifecycle.unmapped`)."""
        return self.lifecycle.unmapped

    # ------------------------------------------------------------------ one movement
    def associate(
        self,
        index: int,
        unique: tuple[Mapping[str, float], Mapping[str, float]],
        detections: tuple[Mapping[str, Sequence[float]], Mapping[str, Sequence[float]]],
        mapped: Mapping[str, LandmarkEstimate],
    ) -> MovementAssociation:
        """Name one movement's detections of shared classes after the landmarks already named.

        Call :meth:`hypothesize` with the result once the estimator has placed the movement.

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
        dets: dict[str, Detections] = {
            c: (
                np.asarray(detections[0].get(c, ()), np.float64),
                np.asarray(detections[1].get(c, ()), np.float64),
            )
            for c in self.capacity
        }
        placed = self._place(index, unique, mapped, dets)
        if isinstance(placed, str):
            out = MovementAssociation(index, assignment=MovementAssignment(index, dets))
            out.report()
            for c, (d1, d2) in dets.items():
                if d1.size + d2.size:
                    out.unresolved[c] = (
                        f"{d1.size + d2.size} detection(s) not associated: movement {placed}"
                    )
            self.lifecycle.weigh(out)
            out.n_hypotheses = self.lifecycle.count()
            return out
        for _ in range(2):  # placed from the unique landmarks, then with the named ones too
            pose, pos_std = placed
            record = self._assign(index, dets, pose, pos_std, mapped)
            out = MovementAssociation(index, pose=pose, assignment=record)
            out.report()
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
        self.lifecycle.weigh(out)
        out.n_hypotheses = self.lifecycle.count()
        return out

    def _assign(
        self,
        index: int,
        dets: Mapping[str, Detections],
        pose: MovementPose,
        pos_std: float,
        mapped: Mapping[str, LandmarkEstimate],
    ) -> MovementAssignment:
        """Predict the named landmarks of each class detected at O1 and at O2 (O1's position
        std ``pos_std``, FL) and assign the detections to them."""
        trusted = self.lifecycle.trusted(mapped)
        predicted: dict[str, tuple[Predicted, Predicted]] = {}
        for c, (d1, d2) in dets.items():
            if d1.size + d2.size == 0:
                continue
            known = self.lifecycle.known(c, mapped)
            predicted[c] = (
                predict_named(known, pose.o1_fl, pose.heading_rad, pos_std**2, self.model, trusted),
                predict_named(known, pose.o2_fl, pose.heading_rad, pos_std**2, self.model, trusted),
            )
        return assign_movement(index, dets, predicted, in_line_rad=self.model.eps_rad)

    def _place(
        self,
        index: int,
        bearings: tuple[Mapping[str, float], Mapping[str, float]],
        mapped: Mapping[str, LandmarkEstimate],
        dets: Mapping[str, Detections] | None = None,
    ) -> tuple[MovementPose, float] | str:
        """The movement's pose and O1's position std (FL) from identified bearings
        (:func:`~pipeline.association.match.place_movement`), else with the detections
        ``dets`` and a placed movement before it by matching every detection with the map;
        else why it cannot be placed."""
        points = {self.reference[0]: np.zeros(2), self.reference[1]: np.array([1.0, 0.0])}
        points.update({n: e.mean_fl for n, e in mapped.items() if n not in self.reference})
        last = self._last[1] if self._last is not None and self._last[0] == index - 1 else None
        after = None if last is None else last.o2_fl
        eps, sigma = self.model.eps_rad, self.model.sigma_rad
        placed = place_movement(bearings, points, after, eps, sigma)
        if not isinstance(placed, str) or after is None or dets is None:
            return placed
        matched = self._match(bearings, mapped, dets, after)
        if matched is None:
            return f"{placed}; its detections match the map nowhere clearly"
        return matched.fit.pose, matched.fit.position_std_fl * sigma

    def _matching_map(
        self, mapped: Mapping[str, LandmarkEstimate]
    ) -> tuple[NDArray[np.float64], list[str]]:
        """The map to match detections with (:func:`~pipeline.association.match.matching_map`)."""
        alike = {n for names in self.named.values() for n in names}
        known = [
            (label, e) for label in self.capacity for _, e in self.lifecycle.known(label, mapped)
        ]
        return matching_map(mapped, self.reference, alike, known)

    def _match(
        self,
        bearings: tuple[Mapping[str, float], Mapping[str, float]],
        mapped: Mapping[str, LandmarkEstimate],
        dets: Mapping[str, Detections],
        o1_fl: NDArray[np.float64],
    ) -> Matched | None:
        """The movement placed by matching every detection (identified or of a shared class)
        with the map, from O1 where the last movement ended (:func:`match_movement`)."""
        pts, labels = self._matching_map(mapped)
        own = set(labels)
        per_class = [{c: d[end].tolist() for c, d in dets.items()} for end in (0, 1)]
        o1, o2 = (all_detections(b, c, own) for b, c in zip(bearings, per_class, strict=True))
        return match_movement(pts, labels, (o1, o2), o1_fl, 0, self.model.eps_rad)

    def hypothesize(
        self,
        out: MovementAssociation,
        pose: MovementPose | None,
        mapped: Mapping[str, LandmarkEstimate],
        trajectory: Mapping[int, MovementPose] | None = None,
        scatter: Mapping[str, tuple[int, float]] | None = None,
    ) -> None:
        """Grow, start, confirm and drop hypotheses with the detections the assignment of
        ``out`` (:meth:`associate`'s result) left free
        (:meth:`pipeline.association.lifecycle.Lifecycle.step`).

        ``pose`` is the movement as the estimator placed it (None: not placed; then the
        association's own placement is used, if any), ``mapped`` the estimator's map after it,
        ``trajectory`` the estimator's current placement of earlier movements (index -> pose):
        rays kept from them are placed anew (early placements, from few landmarks, are
        rough). ``scatter`` is how widely each mapped name's bearings scatter about it
        (:attr:`pipeline.joint.JointSlam.bearing_scatter`; a name that scatters too widely is
        doubtful). Landmarks named now are in ``out.confirmed`` and their bearings in
        ``out.history``; the doubtful and unconfirmed names are reported anew.
        """
        pose = pose or out.pose
        if pose is not None:
            self._last = (out.index, pose)
        self.lifecycle.step(out.assignment, out, pose, mapped, trajectory, scatter)

    # ------------------------------------------------------------------ once the log is processed
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
            noise_rad=self.model.sigma_rad if noise_rad is None else noise_rad,
            eps_rad=self.model.eps_rad,
        )
        given = {c: (len(self.named[c]), n) for c, n in self.capacity.items()}
        return final, missing_reports(final, given, poses, self.model.eps_rad)

    def place_left_out(
        self,
        unique: Mapping[tuple[int, int], Mapping[str, float]],
        detections: Mapping[tuple[int, int], Mapping[str, Sequence[float]]],
        poses: Mapping[tuple[int, int], KeyframePose],
        mapped: Mapping[str, LandmarkEstimate],
        noise_rad: float | None = None,
    ) -> tuple[dict[tuple[int, int], KeyframePose], set[int]]:
        """Once the log is processed: the keyframes of movements the map left out (before the
        map began, or too few of their detections identified) or holds misplaced (a landmark
        of a class of its own seen more than :data:`MISPLACED_EPS` eps from where the map puts
        it: :func:`pipeline.association.match.misplaced`), placed for the association with the
        final map by matching every detection with it, from a placed neighbour
        (:func:`pipeline.association.match.place_left_out`); and the misplaced movements.

        ``unique``: each keyframe's bearings of landmarks of a class of their own (rad);
        ``detections``: its detections per shared class; ``poses`` and ``mapped``: the final
        map; ``noise_rad``: its bearing noise std (default the one eps implies)."""
        pts, labels = self._matching_map(mapped)
        own = set(labels)
        wrong = misplaced(unique, poses, pts, labels, MISPLACED_EPS * self.model.eps_rad)
        held = {key: pose for key, pose in poses.items() if key[0] not in wrong}
        per_keyframe = {
            key: all_detections(unique.get(key, {}), detections.get(key, {}), own)
            for key in set(unique) | set(detections)
        }
        placed = place_left_out(
            per_keyframe,
            held,
            pts,
            labels,
            self.model.eps_rad,
            self.model.sigma_rad if noise_rad is None else noise_rad,
        )
        return placed, wrong

    def repair_final(
        self,
        final: Sequence[FinalDetection],
        poses: Mapping[tuple[int, int], KeyframePose],
        mapped: Mapping[str, LandmarkEstimate],
        index: int,
        noise_rad: float | None = None,
    ) -> MovementAssociation | None:
        """Once the log is processed, give names where the detections the final map leaves
        unexplained meet (:func:`pipeline.association.final.repair_final`): ``final`` is
        :meth:`associate_final`'s association, ``poses`` and ``mapped`` the final map,
        ``index`` the last movement, ``noise_rad`` the bearing noise std it was made with
        (default the one eps implies). Returns what changed, or None when nothing did."""
        sigma = self.model.sigma_rad if noise_rad is None else noise_rad
        return repair_final(self.lifecycle, final, poses, mapped, index, sigma)
