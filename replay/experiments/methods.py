"""Every method on the bearings of one processed log, scored after each movement.

The bearings come from the log's summary (``movements[k].bearings_deg``, what ``bslam process``
extracted), so all methods see exactly the same data: the core estimator with each prior and
particle count, batch least squares on the first k movements, and the Cramér–Rao bound at the
true keyframe positions.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from data_schemas.errors import EstimationError
from pipeline.batch_ls import batch_least_squares
from pipeline.crb import cramer_rao_bound
from pipeline.estimators import make_estimator
from pipeline.slam import BearingSlam, MovementObservation
from replay import defaults
from replay.experiments.results import CRB, ErrorRow
from replay.experiments.scoring import score_rows

Estimates = dict[str, tuple[Any, Any]]


@dataclass(frozen=True)
class RunContext:
    """What scoring one run needs: where its rows go and the truth they are measured against."""

    group: str
    run: int
    landmarks: list[str]
    reference: tuple[str, str]
    scored: list[str]
    truth_fl: dict[str, NDArray[np.float64]]
    scale_cm: float
    vision_error_rad: float

    def rows(self, estimates: Estimates, *, method: str, n_l: int, movement: int) -> list[ErrorRow]:
        """Score one method's estimates after ``movement`` movements."""
        return score_rows(
            estimates,
            self.truth_fl,
            self.scored,
            scale_cm=self.scale_cm,
            group=self.group,
            run=self.run,
            method=method,
            n_l=n_l,
            movement=movement,
        )


def observations_from_summary(summary: dict[str, Any]) -> list[MovementObservation]:
    """The keyframe bearings of every movement of a summary (unseen landmarks left out)."""
    out = []
    for mv in summary["movements"]:
        o1 = {n: math.radians(b[0]) for n, b in mv["bearings_deg"].items() if b[0] is not None}
        o2 = {n: math.radians(b[1]) for n, b in mv["bearings_deg"].items() if b[1] is not None}
        out.append(MovementObservation(int(mv["index"]), o1, o2))
    return out


def summary_rows(summary: dict[str, Any], ctx: RunContext, *, n_l: int) -> list[ErrorRow]:
    """Rows of the impartial estimates the summary holds (the belief after each movement)."""
    rows = []
    for k, mv in enumerate(summary["movements"], start=1):
        est = {n: (e["mean"], e["cov"]) for n, e in mv["landmarks"].items()}
        rows += ctx.rows(est, method="impartial", n_l=n_l, movement=k)
    return rows


def estimator_rows(
    observations: Sequence[MovementObservation],
    ctx: RunContext,
    *,
    prior: str,
    n_r: int,
    n_l: int,
    frame_change: str,
    rng: np.random.Generator,
) -> list[ErrorRow]:
    """Run the sequential estimator with ``prior`` over the observations; score each belief."""
    slam = BearingSlam(
        ctx.landmarks,
        ctx.reference,
        vision_error_rad=ctx.vision_error_rad,
        prior=prior,  # type: ignore[arg-type]
        n_r=n_r,
        n_l=n_l,
        frame_change=frame_change,  # type: ignore[arg-type]
        rng=rng,
    )
    rows = []
    for k, obs in enumerate(observations, start=1):
        result = slam.process_movement(obs)
        est = {n: (e.mean_fl, e.cov_fl) for n, e in result.estimates.items()}
        rows += ctx.rows(est, method=prior, n_l=n_l, movement=k)
    return rows


def joint_rows(
    observations: Sequence[MovementObservation],
    ctx: RunContext,
    *,
    n_r: int,
    n_l: int,
    rng: np.random.Generator,
    distance_prior_rel: float | None,
) -> list[ErrorRow]:
    """Run the joint estimator (initialized by the paper's filter) over the observations, with
    a prior on each movement's length from ``distance_m`` if ``distance_prior_rel`` is given."""
    slam = make_estimator(
        "joint",
        ctx.landmarks,
        ctx.reference,
        vision_error_rad=ctx.vision_error_rad,
        prior="impartial",  # the joint method is initialized by the paper's impartial PDF
        n_r=n_r,
        n_l=n_l,
        rng=rng,
        turn_prior_sigma_rad=None,  # simulated straight movements: no commanded turn is trusted
        distance_prior_rel=distance_prior_rel,
        window=defaults.JOINT_WINDOW,
    )
    rows = []
    for k, obs in enumerate(observations, start=1):
        result = slam.process_movement(obs)
        est = {n: (e.mean_fl, e.cov_fl) for n, e in result.estimates.items()}
        rows += ctx.rows(est, method="joint", n_l=0, movement=k)
    return rows


def batch_ls_rows(observations: Sequence[MovementObservation], ctx: RunContext) -> list[ErrorRow]:
    """Batch least squares on the first k movements, for every k (no credible region)."""
    rows = []
    for k in range(1, len(observations) + 1):
        try:
            means = batch_least_squares(observations[:k], ctx.landmarks, ctx.reference)
        except EstimationError:
            means = {}
        est: Estimates = {n: (m, None) for n, m in means.items()}
        rows += ctx.rows(est, method="batch_ls", n_l=0, movement=k)
    return rows


def crb_rows(
    keyframes_world: Sequence[tuple[NDArray[np.float64], NDArray[np.float64]]],
    landmarks_world: dict[str, NDArray[np.float64]],
    ctx: RunContext,
    sigma_rad: float,
) -> list[ErrorRow]:
    """sqrt(trace(CRB)) with the true O1, O2 of the first k movements as known observers.

    Parameters
    ----------
    keyframes_world : sequence of (o1 (2,), o2 (2,))
        True keyframe positions per movement, metres, world frame.
    landmarks_world : dict of str -> (2,)
        True landmark positions, metres, world frame.
    sigma_rad : float
        Std of the bearing noise.
    """
    rows = []
    for k in range(1, len(keyframes_world) + 1):
        observers = np.array([p for pair in keyframes_world[:k] for p in pair])
        for name in ctx.scored:
            bound = cramer_rao_bound(landmarks_world[name], observers, sigma_rad)
            cm = 100.0 * math.sqrt(float(np.trace(bound)))
            rows.append(ErrorRow(ctx.group, ctx.run, CRB, 0, k, name, cm / ctx.scale_cm, cm, None))
    return rows
