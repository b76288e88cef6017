"""Initialization of one landmark in FR (docs/method.md, part 3).

:func:`initialize_fr` (the paper): uniform draws in ``A_i``, importance weights ``p1 p2`` (the
chosen prior seen from O1 and O2), one systematic resampling to ``n_r`` equally weighted
particles.

:func:`sample_fr_posterior`: the same distribution, drawn through the bearing errors, cheap
enough for large sets (the frame marginalisation of :mod:`pipeline.likelihood` needs a finely
resolved frame: 50 particles, about 35 distinct after resampling, make the movement's
likelihood lumpy, an error shared by every point of the belief). Draw ``e1, e2 ~ g`` and
triangulate the rays ``b1 + e1`` from O1 and ``b2 + e2`` from O2 at ``z``. With ``r1, r2`` the
ranges and ``gamma`` the angle between the rays at ``z``, the area element is
``dz = r1 r2 / |sin gamma| de1 de2``, so ``z`` has density ``g(e1) g(e2) |sin gamma| / (r1 r2)``
and the weight ``p1(z) p2(z) r1 r2 / (g(e1) g(e2) |sin gamma|)`` makes the draws exact for any
prior (for the impartial prior with the same ``g``: ``1 / |sin gamma|`` on the range annuli).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pipeline.cones import O1_FR, O2_FR, ConeIntersection, Degenerate
from pipeline.priors import ImpartialPrior, Prior
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


def sample_fr_posterior(
    region: ConeIntersection,
    prior: Prior,
    noise: ImpartialPrior,
    n: int,
    rng: np.random.Generator,
) -> NDArray[np.float64] | Degenerate:
    """``n`` equally weighted draws (n, 2) FR from ``∝ p1 p2`` on ``A_i``, or why not.

    Parameters
    ----------
    region : ConeIntersection
        ``A_i`` (its bearings and range bounds are used).
    prior : Prior
        Single-bearing prior giving ``p1`` and ``p2``.
    noise : ImpartialPrior
        Its ``g`` (zero outside ``[-eps, eps]``) proposes the bearing errors.
    n : int
    rng : numpy.random.Generator
    """
    b1, b2 = region.bearings_rad
    e1 = noise.sample_angle(n, rng)
    e2 = noise.sample_angle(n, rng)
    t1, t2 = b1 + e1, b2 + e2
    sin_g = np.sin(t2 - t1)  # never 0: |parallax| > 2 eps for a ConeIntersection
    r1 = np.sin(t2) / sin_g
    r2 = np.sin(t1) / sin_g
    lo, hi = region.r_min, region.r_max
    ok = (r1 >= lo) & (r1 <= hi) & (r2 >= lo) & (r2 <= hi)
    z = np.column_stack((r1 * np.cos(t1), r1 * np.sin(t1)))[ok]
    den = noise.g_product(e1[ok], e2[ok]) * np.abs(sin_g[ok])
    num = prior.density(z, O1_FR, b1) * prior.density(z, O2_FR, b2) * (r1[ok] * r2[ok])
    w = np.where(den > 0.0, num / np.where(den > 0.0, den, 1.0), 0.0)
    if not float(w.sum()) > 0.0:
        return Degenerate("no bearing-error draw lands in the range bounds")
    return z[systematic_resample(w, n, rng)]
