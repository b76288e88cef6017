"""Which estimator makes the map: the paper's filter or the joint factor graph (the default).

Both take one :class:`~pipeline.slam.MovementObservation` per movement and return a
:class:`~pipeline.slam.MovementResult` (the joint one a
:class:`~pipeline.joint.JointMovementResult`) with ``estimates`` (mean, covariance, credible
ellipse per landmark, FL). ``gtsam`` is imported only when the joint estimator is made.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal, Protocol

import numpy as np

from data_schemas.errors import EstimationError
from pipeline.estimate import LandmarkEstimate
from pipeline.fusion import PAPER_N_L
from pipeline.priors import PriorName
from pipeline.slam import BearingSlam, MovementObservation, MovementResult

EstimatorName = Literal["joint", "paper"]
#: Estimator names, the default first.
ESTIMATORS: tuple[EstimatorName, ...] = ("joint", "paper")
DEFAULT_ESTIMATOR: EstimatorName = "joint"


class Estimator(Protocol):
    """What the stages need from an estimator."""

    def process_movement(self, obs: MovementObservation) -> MovementResult:
        """Fold one movement's bearings into the map."""

    @property
    def estimates(self) -> dict[str, LandmarkEstimate]:
        """The current map: non-reference landmarks, FL."""

    def forget(self, name: str) -> None:
        """Drop landmark ``name`` and what it was given so far (its name was found wrong)."""


#: Default relative std of the joint estimator's prior on each movement's length from its driven
#: distance (docs/method.md, the joint estimator: measured on the paper protocol).
DEFAULT_DISTANCE_PRIOR_REL = 0.05


def make_estimator(
    name: str,
    landmarks: Sequence[str],
    reference: tuple[str, str],
    *,
    vision_error_rad: float,
    rng: np.random.Generator,
    prior: PriorName = "impartial",
    n_r: int = 50,
    n_l: int = PAPER_N_L,
    turn_prior_sigma_rad: float | None = None,
    distance_prior_rel: float | None = None,
) -> Estimator:
    """The estimator called ``name`` (``"joint"`` or ``"paper"``), set up for one run.

    ``paper`` is :class:`~pipeline.slam.BearingSlam` exactly as the paper's method;
    ``joint`` is :class:`~pipeline.joint.JointSlam`, initialized by the same filter.
    ``turn_prior_sigma_rad`` and ``distance_prior_rel`` only concern the joint estimator.
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
            **common,  # type: ignore[arg-type]
        )
    raise EstimationError(f"unknown estimator {name!r}; use one of {', '.join(ESTIMATORS)}")
