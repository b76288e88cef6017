"""Initialization of one landmark in FR (METHOD.md section 3).

Uniform draws in ``A_i``, importance weights ``p1 p2`` (the chosen prior seen from O1 and O2),
one systematic resampling to ``n_r`` equally weighted particles.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pipeline.cones import O1_FR, O2_FR, ConeIntersection, Degenerate
from pipeline.priors import Prior
from pipeline.resample import systematic_resample

#: Uniform draws per output particle.
DRAWS_PER_PARTICLE = 20


def initialize_fr(
    region: ConeIntersection,
    prior: Prior,
    n_r: int,
    rng: np.random.Generator,
    *,
    draws_per_particle: int = DRAWS_PER_PARTICLE,
) -> NDArray[np.float64] | Degenerate:
    """Particle set ``S_i`` (n_r, 2) in FR for a landmark in ``region``, or why not.

    Parameters
    ----------
    region : ConeIntersection
        ``A_i`` from :func:`pipeline.cones.intersect_cones`.
    prior : Prior
        Single-bearing prior giving ``p1`` and ``p2``.
    n_r : int
        Output particles (equally weighted).
    rng : numpy.random.Generator
    draws_per_particle : int
        Uniform proposals per output particle.
    """
    pts = region.sample_uniform(draws_per_particle * n_r, rng)
    if pts.shape[0] == 0:
        return Degenerate("the cone intersection is too thin to sample")
    b1, b2 = region.bearings_rad
    w = prior.density(pts, O1_FR, b1) * prior.density(pts, O2_FR, b2)
    if not float(w.sum()) > 0.0:
        return Degenerate("the prior gives zero weight everywhere in the cone intersection")
    return pts[systematic_resample(w, n_r, rng)]
