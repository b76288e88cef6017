"""Bearing likelihood of one movement in FL, marginalised over that movement's frame.

Where a movement lies in FL (O1, O2 and the heading) is known only through the reference
landmarks' FR particle sets ``S1``, ``S2``: each pair ``(s1, s2)`` is one possible frame. For a
point ``x`` in FL and one pair, the same point in FR is ``z = s1 + x (s2 - s1)`` (complex
numbers: the inverse of :func:`pipeline.frame_change.to_fl`); its bearings are ``arg z`` from
``O1 = 0`` and ``arg(z - 1)`` from ``O2 = 1``. The likelihood of the measured bearings
``b1, b2`` of a landmark at ``x`` is

    L_t(x) = E_(s1, s2) [ g(arg z - b1) g(arg(z - 1) - b2) ]

(``g`` the angular density of the bearing error, zero outside ``[-eps, eps]``): the frame is
marginalised, and no range prior enters, so fusing ``L_t`` counts the prior once.

:func:`frame_marginal_likelihood` estimates ``L_t`` without bias by the mean over ``n_frames``
pairs drawn independently **for every point**. Pairs shared by all points would make the
estimate's error common to all points, a systematic error per movement that the fused belief
cannot see (measured: the 80% region then covers the truth in about 53% of trials).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pipeline.priors import ImpartialPrior

#: Frame pairs averaged per point.
N_FRAMES = 16
#: (point, pair) evaluations per block.
BLOCK_PAIRS = 8192


def _by_range(points_fr: NDArray[np.float64]) -> NDArray[np.complex64]:
    """Points (n, 2) FR as complex64 (n,), sorted by range from O1."""
    z = points_fr[:, 0] + 1j * points_fr[:, 1]
    out: NDArray[np.complex64] = z[np.argsort(np.abs(z))].astype(np.complex64)
    return out


def _strata(n_frames: int) -> NDArray[np.float32]:
    """Row ``c`` (n_frames,): strata ``(k + c) mod n_frames`` for ``k = 0 .. n_frames - 1``."""
    k = np.arange(n_frames)
    out: NDArray[np.float32] = ((k[None, :] + k[:, None]) % n_frames).astype(np.float32)
    return out


def frame_marginal_likelihood(
    points_fl: NDArray[np.float64],
    ref1_fr: NDArray[np.float64],
    ref2_fr: NDArray[np.float64],
    bearing_o1_rad: float,
    bearing_o2_rad: float,
    noise: ImpartialPrior,
    rng: np.random.Generator,
    *,
    n_frames: int = N_FRAMES,
) -> NDArray[np.float64]:
    """Unbiased estimate of ``L_t`` at points (m, 2) FL; returns (m,) (units of ``g^2``).

    The ``n_frames`` pairs of a point are a Latin-hypercube draw: both sets are sorted by
    range (the direction in which a frame is least certain) and cut into ``n_frames`` strata;
    pair ``k`` takes a uniform member of stratum ``k`` of ``S1`` and of stratum ``k + c``
    (mod ``n_frames``, ``c`` random per point) of ``S2``. Each pair is thus uniform over
    ``S1 x S2`` on average (unbiased) while the strata cover both sets evenly (measured: half
    the variance of independent pairs). Arithmetic in float32 (angles to ~1e-6 rad, against
    ``eps`` ~ 0.05 rad).

    Parameters
    ----------
    points_fl : ndarray (m, 2)
        Candidate landmark positions (FL).
    ref1_fr, ref2_fr : ndarray (n1, 2), (n2, 2)
        Particle sets of the reference landmarks in this movement's FR.
    bearing_o1_rad, bearing_o2_rad : float
        The landmark's measured bearings at O1 and O2 (robot frame = FR).
    noise : ImpartialPrior
        Its angular density ``g`` is the bearing-error density.
    rng : numpy.random.Generator
    n_frames : int
        Pairs ``(s1, s2)`` drawn per point.
    """
    m = points_fl.shape[0]
    f32 = np.float32
    s1 = _by_range(ref1_fr)
    s2 = _by_range(ref2_fr)
    strata = _strata(n_frames)
    w1, w2 = f32(s1.size / n_frames), f32(s2.size / n_frames)
    rot1 = np.complex64(np.exp(-1j * bearing_o1_rad))  # turns the measured ray onto +x
    rot2 = np.complex64(np.exp(-1j * bearing_o2_rad))
    x_all = (points_fl[:, 0] + 1j * points_fl[:, 1]).astype(np.complex64)[:, None]
    shift = rng.integers(0, n_frames, (m,))
    out = np.empty(m)
    rows = max(1, BLOCK_PAIRS // n_frames)  # blocks keep temporaries small (no page faults)
    for start in range(0, m, rows):
        x = x_all[start : start + rows]
        k = x.shape[0]
        u1 = rng.random((k, n_frames), dtype=f32)  # position in the stratum, [0, 1)
        u2 = rng.random((k, n_frames), dtype=f32)
        i = ((strata[0] + u1) * w1).astype(np.intp)
        j = ((strata[shift[start : start + rows]] + u2) * w2).astype(np.intp)
        # z = (1 - x) s1 + x s2: the point in FR for the pair (s1, s2)
        z = ((1 - x) * np.take(s1, i, mode="clip") + x * np.take(s2, j, mode="clip")).ravel()
        z1 = z * rot1
        da1 = np.arctan2(z1.imag, z1.real)
        # most pairs miss the cone at O1 (g = 0): finish only the others
        hit = np.flatnonzero(np.abs(da1) <= noise.eps_rad)
        z2 = (z[hit] - 1) * rot2
        g = noise.g_product(da1[hit], np.arctan2(z2.imag, z2.real))
        out[start : start + k] = np.bincount(hit // n_frames, g, minlength=k) / n_frames
    return out


__all__ = ["N_FRAMES", "frame_marginal_likelihood"]
