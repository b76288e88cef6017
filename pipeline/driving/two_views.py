"""The impartial-PDF initialization of a landmark from two views with any known relative pose.

The paper initializes a landmark from the two keyframes of one straight movement, in FR
(O1 = (0, 0), O2 = (1, 0)). Two views from anywhere reduce to that case: the similarity that
sends the first sensor position to (0, 0) and the second to (1, 0)
(:func:`pipeline.frame_change.to_fl`) turns each view's ray into a bearing in that frame (the
ray's direction minus the baseline's), and the range bounds into baseline units. The cones, the
prior and the posterior draws are then exactly the straight movement's
(:func:`pipeline.cones.intersect_cones`, :func:`pipeline.init_fr.sample_fr_posterior`), and the
particles go back with the inverse similarity.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad
from pipeline.cones import Degenerate, intersect_cones
from pipeline.frame_change import from_fl
from pipeline.init_fr import sample_fr_posterior
from pipeline.priors import ImpartialPrior, PriorName, make_prior


def initialize_two_views(
    view1: NDArray[np.float64],
    bearing1_rad: float,
    view2: NDArray[np.float64],
    bearing2_rad: float,
    *,
    eps_rad: float,
    r_min_m: float,
    r_max_m: float,
    n: int,
    rng: np.random.Generator,
    prior: PriorName = "impartial",
) -> NDArray[np.float64] | Degenerate:
    """Particles (n, 2) of a landmark seen from two sensor poses, in their frame (m), or why not.

    Parameters
    ----------
    view1, view2 : (3,) float
        Sensor poses ``(x (m), y (m), heading (rad))`` in one frame.
    bearing1_rad, bearing2_rad : float
        The landmark's bearing from each, relative to its heading (CCW).
    eps_rad : float
        Bound on the bearing error.
    r_min_m, r_max_m : float
        Range bounds (m) of the prior.
    n : int
        Equally weighted particles wanted.
    rng : numpy.random.Generator
    prior : {"impartial", "gaussian", "mixture"}
        Single-bearing prior.
    """
    s1 = np.asarray(view1[:2], np.float64)
    s2 = np.asarray(view2[:2], np.float64)
    baseline_m = math.hypot(*(s2 - s1))
    if not baseline_m > 0.0:
        return Degenerate("the two views are at the same place")
    toward = math.atan2(s2[1] - s1[1], s2[0] - s1[0])
    b1 = float(wrap_rad(float(view1[2]) + bearing1_rad - toward))
    b2 = float(wrap_rad(float(view2[2]) + bearing2_rad - toward))
    r_min, r_max = r_min_m / baseline_m, r_max_m / baseline_m
    region = intersect_cones(b1, b2, eps_rad, r_min, r_max)
    if isinstance(region, Degenerate):
        return region
    noise = ImpartialPrior(eps_rad, r_min, r_max)
    fr = sample_fr_posterior(region, make_prior(prior, eps_rad, r_min, r_max), noise, n, rng)
    if isinstance(fr, Degenerate):
        return fr
    return from_fl(fr, s1, s2)
