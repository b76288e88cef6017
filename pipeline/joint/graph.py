"""GTSAM factors of the joint map: keys, bearing factors, movement constraints, gauge.

One ``Pose2`` per keyframe (key ``x(2 k + end)``, ``end`` 0 at O1 and 1 at O2 of movement k),
one ``Point2`` per landmark (key ``l(j)``, ``j`` its catalog index). FL units (|L1 L2| = 1).
With a distance prior, one more variable: the map's scale, ``log`` of FL units per metre (key
:data:`SCALE_KEY`, a 1-vector), which ties every movement's length in FL to its distance in metres.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import gtsam
import numpy as np
from numpy.typing import NDArray

#: Std of the "drives straight" constraint: lateral offset (FL) and heading change (rad).
STRAIGHT_SIGMA = (1e-3, 1e-3)
#: Std of the "turns in place" constraint on the position (FL).
IN_PLACE_SIGMA_FL = 1e-3
#: Std of the gauge priors L1 = (0, 0), L2 = (1, 0) (FL).
GAUGE_SIGMA_FL = 1e-4
#: Std of the weak priors that keep every new variable determined (FL; rad for headings).
WEAK_SIGMA = 100.0
#: Huber threshold, in standard deviations of the bearing noise.
HUBER_K = 1.345
#: Loose std (FL) for the length of a movement: a free variable in practice.
FREE_LENGTH_SIGMA_FL = 100.0


#: iSAM2 relinearizes a variable once its update since the last linearization exceeds this:
#: keyframe (x, y in FL, heading in rad), landmark (x, y in FL), log scale.
RELINEARIZE_POSE = (5e-3, 5e-3, 5e-3)
RELINEARIZE_POINT_FL = 5e-3
RELINEARIZE_LOG_SCALE = 5e-3


def relinearize_thresholds() -> gtsam.ISAM2ThresholdMap:
    """Per-variable relinearization thresholds for iSAM2, by key letter."""
    out = gtsam.ISAM2ThresholdMap()
    out.insert(("x", np.array(RELINEARIZE_POSE)))
    out.insert(("l", np.full(2, RELINEARIZE_POINT_FL)))
    out.insert(("s", np.array([RELINEARIZE_LOG_SCALE])))
    return out


#: Key of the map's scale (log of FL units per metre), present only with a distance prior.
SCALE_KEY = int(gtsam.symbol("s", 0))


def pose_key(movement: int, end: int) -> int:
    """Key of the keyframe pose: movement index, ``end`` 0 (O1) or 1 (O2)."""
    return int(gtsam.symbol("x", 2 * movement + end))


def landmark_key(index: int) -> int:
    """Key of the landmark with catalog index ``index``."""
    return int(gtsam.symbol("l", index))


@dataclass(frozen=True)
class Bearing:
    """One detected bearing in the graph.

    Attributes
    ----------
    movement : int
        Movement index.
    end : int
        0 at O1, 1 at O2.
    landmark : str
        Landmark name.
    bearing_rad : float
        Measured bearing (robot frame, CCW, 0 = forward).
    """

    movement: int
    end: int
    landmark: str
    bearing_rad: float


@functools.lru_cache(maxsize=32)
def _isotropic(dim: int, sigma: float) -> gtsam.noiseModel.Isotropic:
    """An isotropic noise model (made once per dimension and std: models are immutable)."""
    return gtsam.noiseModel.Isotropic.Sigma(dim, sigma)


@functools.lru_cache(maxsize=32)
def _diagonal(sigmas: tuple[float, ...]) -> gtsam.noiseModel.Diagonal:
    """A diagonal noise model (made once per set of stds)."""
    return gtsam.noiseModel.Diagonal.Sigmas(np.array(sigmas))


@functools.lru_cache(maxsize=32)
def bearing_noise(sigma_rad: float, robust: bool = True) -> gtsam.noiseModel.Base:
    """Isotropic noise of std ``sigma_rad`` on one scalar error (a bearing's, or a length's),
    under a Huber loss unless ``robust`` is off (made once per std)."""
    base = _isotropic(1, sigma_rad)
    if not robust:
        return base
    return gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(HUBER_K), base)


def bearing_factor(
    pose: int, landmark: int, bearing_rad: float, noise: gtsam.noiseModel.Base
) -> gtsam.NonlinearFactor:
    """Bearing of a landmark (Point2) seen from a keyframe (Pose2)."""
    return gtsam.BearingFactor2D(pose, landmark, gtsam.Rot2(bearing_rad), noise)


def straight_factor(
    o1: int, o2: int, length_fl: float | None = None, length_sigma_fl: float = 0.0
) -> gtsam.NonlinearFactor:
    """O2 is ahead of O1 along O1's x axis with the same heading; length free unless given."""
    if length_fl is None:
        length_fl, length_sigma_fl = 1.0, FREE_LENGTH_SIGMA_FL
    noise = _diagonal((length_sigma_fl, *STRAIGHT_SIGMA))
    return gtsam.BetweenFactorPose2(o1, o2, gtsam.Pose2(length_fl, 0.0, 0.0), noise)


def in_place_factor(
    o2_prev: int, o1_next: int, turn_rad: float | None, turn_sigma_rad: float
) -> gtsam.NonlinearFactor:
    """The robot turns in place: same position; the turn is free unless ``turn_rad`` is given."""
    sigma_turn = WEAK_SIGMA if turn_rad is None else turn_sigma_rad
    noise = _diagonal((IN_PLACE_SIGMA_FL, IN_PLACE_SIGMA_FL, sigma_turn))
    return gtsam.BetweenFactorPose2(o2_prev, o1_next, gtsam.Pose2(0.0, 0.0, turn_rad or 0.0), noise)


def gauge_factors(l1: int, l2: int) -> list[gtsam.NonlinearFactor]:
    """L1 = (0, 0), L2 = (1, 0)."""
    noise = gtsam.noiseModel.Isotropic.Sigma(2, GAUGE_SIGMA_FL)
    return [
        gtsam.PriorFactorPoint2(l1, np.array([0.0, 0.0]), noise),
        gtsam.PriorFactorPoint2(l2, np.array([1.0, 0.0]), noise),
    ]


def weak_point_prior(key: int, point_fl: NDArray[np.float64]) -> gtsam.NonlinearFactor:
    """A very wide prior at a landmark's initial value (keeps the system determined)."""
    return gtsam.PriorFactorPoint2(key, point_fl, _isotropic(2, WEAK_SIGMA))


def weak_pose_prior(key: int, pose: gtsam.Pose2) -> gtsam.NonlinearFactor:
    """A very wide prior at a keyframe's initial value (keeps the system determined)."""
    return gtsam.PriorFactorPose2(key, pose, _isotropic(3, WEAK_SIGMA))


def distance_factor(
    o1: int, o2: int, distance_m: float, rel_sigma: float, robust: bool = True
) -> gtsam.NonlinearFactor:
    """Movement length |O2 - O1| (FL) = scale (FL per metre) x ``distance_m``, relative std
    ``rel_sigma``: error ``log |O2 - O1| - log_scale - log distance_m`` (Huber unless not
    ``robust``; a wheel that slipped a lot must not drag the map's scale)."""
    log_d = math.log(distance_m)

    def error(
        this: gtsam.CustomFactor, values: gtsam.Values, jac: list[NDArray[np.float64]] | None
    ) -> NDArray[np.float64]:
        p1, p2 = values.atPose2(this.keys()[0]), values.atPose2(this.keys()[1])
        log_scale = float(values.atVector(this.keys()[2])[0])
        dx, dy = p2.x() - p1.x(), p2.y() - p1.y()
        length2 = max(dx * dx + dy * dy, 1e-18)
        if jac is not None:
            # d log|d| / d (world position) = d^T / |d|^2; Pose2 moves in its body frame
            for i, (pose, sign) in enumerate(((p1, -1.0), (p2, 1.0))):
                c, s = math.cos(pose.theta()), math.sin(pose.theta())
                gx, gy = sign * dx / length2, sign * dy / length2
                jac[i] = np.array([[gx * c + gy * s, -gx * s + gy * c, 0.0]])
            jac[2] = np.array([[-1.0]])
        return np.array([0.5 * math.log(length2) - log_scale - log_d])

    return gtsam.CustomFactor(bearing_noise(rel_sigma, robust), [o1, o2, SCALE_KEY], error)


def weak_scale_prior(log_scale: float) -> gtsam.NonlinearFactor:
    """A very wide prior at the scale's initial value (keeps the system determined)."""
    return gtsam.PriorFactorVector(SCALE_KEY, np.array([log_scale]), _isotropic(1, WEAK_SIGMA))


#: Iterations of a batch Levenberg-Marquardt solve (:func:`solve_batch`).
BATCH_MAX_ITERATIONS = 100


def solve_batch(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> gtsam.Values:
    """``values`` refined by Levenberg-Marquardt over ``graph`` (at most
    :data:`BATCH_MAX_ITERATIONS` iterations); raises ``RuntimeError`` when GTSAM finds the
    system indeterminate."""
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(BATCH_MAX_ITERATIONS)
    return gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
