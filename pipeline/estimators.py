"""Which estimator makes the map: the paper's filter or the joint factor graph (the default).

Both take one :class:`~pipeline.slam.MovementObservation` per movement and return a
:class:`~pipeline.slam.MovementResult` (the joint one a
:class:`~pipeline.joint.JointMovementResult`) with ``estimates`` (mean, covariance, credible
ellipse per landmark, FL). ``gtsam`` is imported only when the joint estimator is made.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Literal, Protocol

import numpy as np

from data_schemas.errors import EstimationError
from pipeline.estimate import LandmarkEstimate
from pipeline.priors import PriorName
from pipeline.slam import BearingSlam, MovementObservation, MovementResult

if TYPE_CHECKING:
    from pipeline.geometry import KeyframePose, MovementPose
    from pipeline.joint.noise import NoiseEstimate

EstimatorName = Literal["joint", "paper"]
#: Estimator names (the default first, as ``replay.defaults.ESTIMATORS``).
ESTIMATORS: tuple[EstimatorName, ...] = ("joint", "paper")


class Estimator(Protocol):
    """What the stages need from an estimator."""

    def process_movement(self, obs: MovementObservation) -> MovementResult:
        """Fold one movement's bearings into the map."""

    @property
    def estimates(self) -> dict[str, LandmarkEstimate]:
        """The current map: non-reference landmarks, FL."""

    def forget(self, name: str) -> None:
        """Drop landmark ``name`` and what it was given so far (its name was found wrong)."""


class AssociatingEstimator(Estimator, Protocol):
    """What association of landmarks that look alike needs from the estimator besides
    (:class:`pipeline.association.alike.AlikeLandmarks`): the joint estimator has it."""

    @property
    def noise(self) -> NoiseEstimate | None:
        """Bearing noise estimated from the map's residuals (None: not yet)."""

    @property
    def marginals(self) -> dict[str, LandmarkEstimate]:
        """Per landmark: its point and linearized marginal (FL), what predictions from the
        keyframes combine with the keyframes' covariances."""

    def movement_poses(self) -> dict[int, MovementPose]:
        """Every movement in the map, by index (in order), as it is placed now (FL)."""

    @property
    def bearing_scatter(self) -> dict[str, tuple[int, float]]:
        """Per landmark: its bearings in the map and their scatter over the map's noise."""

    def keyframe_poses(self) -> dict[tuple[int, int], KeyframePose]:
        """Every keyframe in the map, ``(movement, end)``, with its pose and covariance (FL)."""

    def add_history(self, name: str, bearings: Sequence[tuple[int, int, float]]) -> None:
        """Bearings ``(movement, end, bearing_rad)`` of ``name`` known only once it is named."""

    def settle(self) -> list[str]:
        """Enter the landmarks whose bearings wait and update the map; their names."""

    def rebear(
        self,
        bearings: Mapping[str, Sequence[tuple[int, int, float]]],
        moved: Mapping[int, MovementPose] | None = None,
    ) -> None:
        """Give landmarks in the map exactly ``bearings`` (name -> ``(movement, end,
        bearing_rad)``) in place of theirs and solve the map again, the ``moved`` movements
        (index -> pose, FL) starting from those poses."""


def associating(estimator: Estimator) -> AssociatingEstimator:
    """``estimator`` as association drives it: the joint estimator.

    Raises
    ------
    EstimationError
        ``estimator`` is another (the paper's filter cannot take a landmark's bearings from
        before it was named).
    """
    from pipeline.joint.estimator import JointSlam

    if not isinstance(estimator, JointSlam):
        raise EstimationError(
            "landmarks that look alike are associated with the joint estimator only; "
            "use --estimator joint"
        )
    return estimator


def make_estimator(
    name: str,
    landmarks: Sequence[str],
    reference: tuple[str, str],
    *,
    vision_error_rad: float,
    rng: np.random.Generator,
    prior: PriorName,
    n_r: int,
    n_l: int,
    turn_prior_sigma_rad: float | None,
    distance_prior_rel: float | None,
    window: int | None,
) -> Estimator:
    """The estimator called ``name`` (``"joint"`` or ``"paper"``), set up for one run.

    ``paper`` is :class:`~pipeline.slam.BearingSlam` exactly as the paper's method;
    ``joint`` is :class:`~pipeline.joint.JointSlam`, initialized by the same filter.
    ``turn_prior_sigma_rad``, ``distance_prior_rel`` and ``window`` (movements kept in the
    graph, None: every one) only concern the joint estimator. Every
    setting is given: the defaults live in one place, ``replay.defaults`` (used through
    ``replay.records.MethodConfig`` and ``replay.estimation.estimator_for``).
    """
    common = {"vision_error_rad": vision_error_rad, "prior": prior, "n_r": n_r, "n_l": n_l}
    if name == "paper":
        return BearingSlam(landmarks, reference, rng=rng, **common)  # type: ignore[arg-type]
    if name == "joint":
        from pipeline.joint.estimator import JointSlam

        return JointSlam(
            landmarks,
            reference,
            rng=rng,
            turn_prior_sigma_rad=turn_prior_sigma_rad,
            distance_prior_rel=distance_prior_rel,
            window=window,
            **common,  # type: ignore[arg-type]
        )
    raise EstimationError(f"unknown estimator {name!r}; use one of {', '.join(ESTIMATORS)}")
