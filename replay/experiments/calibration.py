"""Calibration of the joint map per arena family: do its 80% regions hold the truth 80% of the time?

One run: simulate a log of a family's scenario (:mod:`replay.experiments.families`), extract its
bearings (``bslam process``), run the joint estimator on them (distance prior as the default)
and batch least squares, and score every landmark of the final map: its error, batch least
squares' error, and the squared Mahalanobis distance of the truth under the map's covariance
(inside the 80% region when at most the chi-square(2) quantile).
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from data_schemas.errors import EstimationError
from pipeline.batch_ls import batch_least_squares
from pipeline.estimators import Estimator, make_estimator
from pipeline.slam import MovementObservation
from replay import defaults
from replay.experiments.families import family_scenario
from replay.experiments.methods import observations_from_summary
from replay.experiments.run import read_log_plan, simulate
from replay.experiments.scoring import CHI2_2_LEVEL
from replay.truth import truth_from_scenario


@dataclass(frozen=True)
class LandmarkScore:
    """One landmark of one run's final joint map.

    Attributes
    ----------
    family, seed, name : str, int, str
    error_cm, batch_ls_cm : float
        Distance to the truth of the joint map's and of batch least squares' estimate (NaN:
        least squares did not place it).
    d2 : float
        Squared Mahalanobis distance of the truth under the joint map's covariance.
    sigma_deg : float
        The map's estimated bearing noise.
    """

    family: str
    seed: int
    name: str
    error_cm: float
    batch_ls_cm: float
    d2: float
    sigma_deg: float

    @property
    def inside(self) -> bool:
        """Whether the truth lies in the 80% region."""
        return self.d2 <= CHI2_2_LEVEL


def observe_run(family: str, seed: int) -> tuple[dict[str, Any], list[MovementObservation]]:
    """Simulate and process one run of ``family`` drawn from ``seed``: its scenario and the
    keyframe bearings of every movement, with the commanded turn and driven distance."""
    from replay.process import process_log
    from replay.records import MethodConfig

    doc = family_scenario(family, seed)
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / f"{family}_{seed}.mcap"
        simulate(doc, log, seed=seed)
        summary = process_log(log, MethodConfig(seed=seed, estimator="paper")).to_json()
        plan = read_log_plan(log)
    observations = [
        replace(o, turn_rad=plan.turns_rad.get(o.index), distance_m=plan.distances_m.get(o.index))
        for o in observations_from_summary(summary)
    ]
    return doc, observations


def family_estimator(doc: dict[str, Any], seed: int) -> Estimator:
    """The joint estimator as the calibration figures run it on a family's scenario ``doc``:
    replay's defaults (impartial prior, distance prior, window), seeded with ``seed``."""
    return make_estimator(
        "joint",
        [lm["name"] for lm in doc["landmarks"]],
        (doc["reference"][0], doc["reference"][1]),
        vision_error_rad=math.radians(float(doc["vision_error_deg"])),
        rng=np.random.default_rng(seed),
        prior="impartial",
        n_r=defaults.N_R,
        n_l=defaults.N_L,
        turn_prior_sigma_rad=None,
        distance_prior_rel=defaults.DISTANCE_PRIOR_REL,
        window=defaults.JOINT_WINDOW,
    )


def score_observations(
    doc: dict[str, Any], observations: list[MovementObservation], family: str, seed: int
) -> list[LandmarkScore]:
    """Run the joint estimator and batch least squares on a run's bearings; score its final map."""
    reference = (doc["reference"][0], doc["reference"][1])
    truth = truth_from_scenario(doc, reference)
    truth_fl, scale_cm = truth.landmarks_fl(), 100.0 * truth.to_fl.unit_m
    names = [lm["name"] for lm in doc["landmarks"]]
    slam = family_estimator(doc, seed)
    for obs in observations:
        slam.process_movement(obs)
    try:
        ls = batch_least_squares(observations, names, reference)
    except EstimationError:
        ls = {}
    noise = getattr(slam, "noise", None)
    sigma_deg = math.degrees(noise.sigma_rad) if noise is not None else math.nan
    out = []
    for name, est in slam.estimates.items():
        d = est.mean_fl - truth_fl[name]
        cov = np.asarray(est.cov_fl, np.float64)
        d2 = float(d @ np.linalg.solve(cov, d)) if np.linalg.det(cov) > 0.0 else math.inf
        b = ls.get(name)
        ls_cm = math.nan if b is None else scale_cm * float(np.hypot(*(b - truth_fl[name])))
        error_cm = scale_cm * float(np.hypot(*d))
        out.append(LandmarkScore(family, seed, name, error_cm, ls_cm, d2, sigma_deg))
    return out


def score_run(family: str, seed: int) -> list[LandmarkScore]:
    """Simulate, process and score one run of ``family`` drawn from ``seed``."""
    return score_observations(*observe_run(family, seed), family, seed)


def coverage(scores: list[LandmarkScore]) -> float:
    """Share of the landmarks whose truth lies in their 80% region."""
    return float(np.mean([s.inside for s in scores])) if scores else math.nan
