"""The estimator of a run, as the stages use it: made from the method, read into records."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from data_schemas.session import Session
from pipeline.estimators import Estimator, make_estimator
from pipeline.joint.result import JointMovementResult
from pipeline.slam import MovementResult
from replay.records import MethodConfig


def estimator_for(
    method: MethodConfig, session: Session, landmarks: Sequence[str] | None = None
) -> Estimator:
    """The estimator ``method`` asks for, set up for the session's reference and ``landmarks``
    (default: the catalog's names)."""
    turn = None if method.turn_prior_deg is None else math.radians(method.turn_prior_deg)
    return make_estimator(
        method.estimator,
        session.landmark_names() if landmarks is None else landmarks,
        session.reference,
        vision_error_rad=session.vision_error_rad,
        prior=method.prior_name,
        n_r=method.n_r,
        n_l=method.n_l,
        rng=np.random.default_rng(method.seed),
        turn_prior_sigma_rad=turn,
        distance_prior_rel=method.distance_prior,
        window=method.window or None,
    )


def joint_fields(result: MovementResult) -> dict[str, Any]:
    """The :class:`~replay.records.MovementRecord` fields only the joint estimator fills."""
    if not isinstance(result, JointMovementResult):
        return {}
    return {
        "placement": result.placement,
        "residuals_rad": dict(result.residuals_rad),
        "bearing_noise_rad": None if result.noise is None else result.noise.sigma_rad,
        "divergence": result.divergence,
        "solved_again": result.solved_again,
        "map_unit_m": result.unit_m,
        "also_placed": tuple(result.also_placed),
    }
