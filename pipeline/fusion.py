"""Recursive fusion in FL (docs/method.md, part 5), two ways.

:func:`fuse_likelihood` (the default of :class:`pipeline.BearingSlam`):
``q_t = q_{t-1} L_t / ∫ q_{t-1} L_t`` with ``L_t`` this movement's bearing likelihood,
marginalised over the movement's frame (:mod:`pipeline.likelihood`). Proposal: the KDE of the
(weighted) belief ``q_{t-1}`` (a regularised particle filter), so the importance weight is
``L_t`` alone; the ``n_proposal`` weighted draws are the new belief (no reduction to ``n_l`` in
between, which would lose diversity at every movement). When that proposal is poor (effective
sample size below ``n_l``: a wide belief, a narrow likelihood in its tail) the update adds ``m``
draws from a defensive mixture, half from the belief and half from this movement's
own FL set ``p_t``, which covers the product's support; the target is still ``q_{t-1} L_t``.

:func:`fuse` (the paper's literal product) ``q_t = q_{t-1} p_t / ∫ q_{t-1} p_t``, with ``p_t``
the movement's FL particle set. Each ``p_t`` carries the range prior again, so the product
counts the prior once per movement (a bias towards the observation points; docs/method.md).
Proposal: the defensive mixture ``(q^ + p^) / 2`` (half the draws from each KDE), which covers
the product's support wherever either belief has mass; weights
``q^(x) p^(x) / ((q^(x) + p^(x)) / 2)`` in the log domain, one systematic resampling to ``n_l``.

Densities: a Gaussian kernel density estimate with Liu & West (2001) shrinkage: kernel centres
``a x_i + (1 - a) mean``, kernel covariance ``h^2 Cov``, ``a = sqrt(1 - h^2)``, so the KDE keeps
the set's mean and covariance exactly (a plain KDE would inflate the covariance by ``1 + h^2`` at
every fusion step). ``h`` defaults to Scott's factor ``n_eff^(-1/6)`` (2-D).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from pipeline.estimate import LandmarkEstimate
from pipeline.resample import systematic_resample

#: Points per block of :meth:`Kde.logpdf` (a block of exponents stays in the L2 cache).
_LOGPDF_BLOCK = 256
#: Kernel terms below ``exp(-600)`` of the largest are clamped there (no subnormal numbers).
_LOG_NEGLIGIBLE = -600.0


def _chol2(cov: NDArray[np.float64]) -> NDArray[np.float64]:
    """Lower Cholesky factor (2, 2) of a symmetric positive definite (2, 2) matrix."""
    l00 = math.sqrt(cov[0, 0])
    l10 = cov[1, 0] / l00
    return np.array([[l00, 0.0], [l10, math.sqrt(cov[1, 1] - l10 * l10)]])


def _gauss2(n: int, rng: np.random.Generator) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``n`` standard 2-D normal draws as two (n,) arrays (polar Box-Muller).

    From 64 random bits per draw: radius ``sqrt(-2 log U)`` with ``U = (r + 1/2) / 2^32`` from
    32 bits (tail cut at 6.7 sd, probability 2^-32), angle ``2 pi V`` from the other 32 bits,
    its sine and cosine in float32 (1e-7 of a kernel width). Three times faster than
    ``Generator.standard_normal`` here.
    """
    bits = rng.bit_generator.random_raw(n).view(np.uint32)
    r = np.multiply(bits[:n], 2.0**-32)
    r += 2.0**-33
    np.log(r, out=r)
    r *= -2.0
    np.sqrt(r, out=r)
    angle = bits[n:].astype(np.float32)
    angle *= np.float32(2.0 * math.pi * 2.0**-32)
    return r * np.cos(angle), r * np.sin(angle)


@dataclass(frozen=True)
class Kde:
    """Shrinkage Gaussian KDE of a 2-D particle set, optionally weighted (frame of the particles).

    Attributes
    ----------
    centres : ndarray (n, 2)
        Kernel centres in the original frame.
    weights : ndarray (n,)
        Kernel weights (sum 1).
    chol : ndarray (2, 2)
        Lower Cholesky factor of the kernel covariance (for sampling).
    whiten : ndarray (2, 2)
        ``W = chol^-1``: ``W x`` is whitened (kernel covariance = identity).
    log_norm : float
        ``-log(2 pi) - log det(chol)``.
    """

    centres: NDArray[np.float64]
    weights: NDArray[np.float64]
    chol: NDArray[np.float64]
    whiten: NDArray[np.float64]
    log_norm: float

    @classmethod
    def fit(
        cls,
        particles: NDArray[np.float64],
        h: float | None = None,
        *,
        weights: NDArray[np.float64] | None = None,
    ) -> Kde:
        """KDE of ``particles`` (n, 2), equally weighted or with ``weights`` (n,).

        ``h`` defaults to Scott's factor of the effective sample size ``(sum w)^2 / sum w^2``;
        mean and covariance are those of :meth:`LandmarkEstimate.from_particles`.
        """
        x = np.asarray(particles, dtype=np.float64)
        n = x.shape[0]
        w = np.full(n, 1.0 / n) if weights is None else weights / weights.sum()
        hh = float(w @ w) ** (1.0 / 6.0) if h is None else h
        est = LandmarkEstimate.from_particles(x, weights=w)
        ridge = 1e-12 * max(float(np.trace(est.cov_fl)), 1e-12)
        chol = _chol2(hh * hh * (est.cov_fl + ridge * np.eye(2)))
        whiten = np.array(
            [[1.0 / chol[0, 0], 0.0], [-chol[1, 0] / (chol[0, 0] * chol[1, 1]), 1.0 / chol[1, 1]]]
        )
        a = math.sqrt(max(0.0, 1.0 - hh * hh))
        centres_t = np.array(x.T, order="C")  # (2, n) copy: fast rows; centres = its (n, 2) view
        centres_t *= a
        centres_t += ((1.0 - a) * est.mean_fl)[:, None]
        centres = centres_t.T
        log_norm = -math.log(2.0 * math.pi) - math.log(chol[0, 0] * chol[1, 1])
        return cls(centres, w, chol, whiten, log_norm)

    def logpdf(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """Log density at points (m, 2) -> (m,).

        In whitened coordinates about the kernels' mean, the exponent of kernel ``c`` at point
        ``x`` is ``x.c - |c|^2 / 2`` (plus ``-|x|^2 / 2``, outside the sum); per block of points
        (kept in cache) one product ``[x, 1] [c, -|c|^2 / 2]`` gives them, a second one with
        ``-max`` appended gives them anchored at their maximum (log-sum-exp: no underflow far
        from every kernel, no broadcast passes). Terms below ``exp(-600)`` of the largest count
        as ``exp(-600)`` (a relative change below 1e-250; exp is 10-100x slower down there).
        """
        centre = self.centres.T @ self.weights
        cw = (self.centres - centre) @ self.whiten.T
        qw = (points - centre) @ self.whiten.T
        n, k = qw.shape[0], cw.shape[0]
        kernels = np.empty((4, k))  # rows: c_x, c_y, -|c|^2 / 2, 1
        kernels[:2] = cw.T
        kernels[2] = (cw * cw).sum(axis=1)
        kernels[2] *= -0.5
        kernels[3] = 1.0
        rows = np.empty((n, 4))  # columns: x, y, 1, -max
        rows[:, :2] = qw
        rows[:, 2] = 1.0
        out: NDArray[np.float64] = (qw * qw).sum(axis=1)
        out *= -0.5
        out += self.log_norm
        block = np.empty((min(_LOGPDF_BLOCK, n), k))
        for start in range(0, n, _LOGPDF_BLOCK):
            row = rows[start : start + _LOGPDF_BLOCK]
            e = block[: row.shape[0]]
            np.matmul(row[:, :3], kernels[:3], out=e)
            np.negative(e.max(axis=1), out=row[:, 3])
            np.matmul(row, kernels, out=e)
            np.maximum(e, _LOG_NEGLIGIBLE, out=e)
            np.exp(e, out=e)
            out[start : start + row.shape[0]] += np.log(e @ self.weights) - row[:, 3]
        return out

    def sample(self, n: int, rng: np.random.Generator) -> NDArray[np.float64]:
        """``n`` points (n, 2) from the KDE (kernels by systematic resampling of the weights)."""
        out = np.take(self.centres.T, systematic_resample(self.weights, n, rng), axis=1)
        e0, e1 = _gauss2(n, rng)
        (l00, _), (l10, l11) = self.chol
        out[0] += l00 * e0
        e0 *= l10
        e1 *= l11
        e1 += e0
        out[1] += e1
        result: NDArray[np.float64] = out.T
        return result


def _mixture_sample(q: Kde, p: Kde, m: int, rng: np.random.Generator) -> NDArray[np.float64]:
    """``m`` draws (m, 2) from the defensive mixture of two KDEs: ``m - m // 2`` from ``q``,
    then ``m // 2`` from ``p``."""
    return np.vstack((q.sample(m - m // 2, rng), p.sample(m // 2, rng)))


def _mixture_logpdf(
    q: Kde, p: Kde, x: NDArray[np.float64], m: int
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``log q(x)``, ``log p(x)`` and the log density of the mixture of ``m`` draws (k,) at
    points (k, 2) (any subset of the draws: each point's values depend on that point alone)."""
    m_q = m - m // 2
    lq = q.logpdf(x)
    lp = p.logpdf(x)
    log_mix = np.logaddexp(lq + math.log(m_q / m), lp + math.log(max(m // 2, 1) / m))
    return lq, lp, log_mix


def _mixture_draws(
    q: Kde, p: Kde, m: int, rng: np.random.Generator
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``m`` draws from the defensive mixture of two KDEs (``m - m // 2`` from ``q``, the rest
    from ``p``): points (m, 2), ``log q(x)``, ``log p(x)`` and the mixture's log density (m,).
    """
    x = _mixture_sample(q, p, m, rng)
    return (x, *_mixture_logpdf(q, p, x, m))


def fuse(
    prev_fl: NDArray[np.float64],
    new_fl: NDArray[np.float64],
    n_l: int,
    rng: np.random.Generator,
    *,
    h: float | None = None,
    n_proposal: int | None = None,
) -> NDArray[np.float64]:
    """Fused belief (n_l, 2): product of the KDEs of ``prev_fl`` and ``new_fl``, resampled.

    Parameters
    ----------
    prev_fl, new_fl : ndarray (n, 2), (k, 2)
        Previous belief ``q_{t-1}`` and this movement's set ``p_t`` (FL).
    n_l : int
        Output particles.
    rng : numpy.random.Generator
    h : float, optional
        KDE bandwidth factor (default Scott, ``n^(-1/6)``).
    n_proposal : int, optional
        Proposal draws (default ``n_l``), half from each KDE.
    """
    q = Kde.fit(prev_fl, h)
    p = Kde.fit(new_fl, h)
    x, lq, lp, log_mix = _mixture_draws(q, p, n_l if n_proposal is None else n_proposal, rng)
    log_w = lq + lp - log_mix
    w = np.exp(log_w - log_w.max())
    return x[systematic_resample(w, n_l, rng)]


#: Default proposal draws per output particle of :func:`fuse_likelihood`.
PROPOSALS_PER_PARTICLE = 16
#: Particles per landmark in FR (after one movement) and in FL (the belief): the paper's n_r and
#: n_l, the defaults of the filter and the estimators (``replay.defaults`` spells them out for a
#: command line without numpy; a test holds them equal).
PAPER_N_R = 50
PAPER_N_L = 300
#: The defensive mixture draws at most this many points: its two KDE densities (n_l kernels
#: each) at the draws then cost at most ``DEFENSIVE_DRAWS x n_l``, linear in n_l. The paper's
#: n_l = 300 and below draw ``PROPOSALS_PER_PARTICLE n_l``, as before.
DEFENSIVE_DRAWS = PROPOSALS_PER_PARTICLE * PAPER_N_L


class LikelihoodUpdate(NamedTuple):
    """Weighted belief ``∝ q_{t-1} L_t`` from :func:`fuse_likelihood`.

    Attributes
    ----------
    points_fl : ndarray (k, 2)
        Proposals (FL): ``m``, or ``m + m_d`` when the defensive draws were added.
    weights : ndarray (k,)
        Importance weights (not normalised).
    defensive : bool
        Whether defensive mixture draws were used (the plain proposal was poor).
    """

    points_fl: NDArray[np.float64]
    weights: NDArray[np.float64]
    defensive: bool


#: Rows of a density evaluation come in multiples of this (see :func:`_padded`).
_ROW_GROUP = 64


def _padded(index: NDArray[np.intp]) -> NDArray[np.intp]:
    """``index`` (k,) followed by copies of its last entry up to a multiple of ``_ROW_GROUP``.

    BLAS and numpy's SIMD loops treat a partial group of rows at the end of an array with other
    kernels (a different rounding, 1 ulp); rows in whole groups get the same bits wherever they
    are, so a density evaluated at a padded subset of the draws equals, bit for bit, the same
    rows of the evaluation at all of them (whose count, ``16 n_l``, is a multiple of 64 at the
    usual ``n_l``).
    """
    pad = -index.size % _ROW_GROUP
    return np.concatenate((index, np.full(pad, index[-1]))) if pad else index


def _ess(w: NDArray[np.float64]) -> float:
    """Effective sample size ``(sum w)^2 / sum w^2`` of weights (m,) (0 if all are 0)."""
    total = float(w.sum())
    return total * total / float(w @ w) if total > 0.0 else 0.0


def fuse_likelihood(
    prev_fl: NDArray[np.float64],
    likelihood: Callable[[NDArray[np.float64]], NDArray[np.float64]],
    n_l: int,
    rng: np.random.Generator,
    *,
    prev_weights: NDArray[np.float64] | None = None,
    new_fl: NDArray[np.float64] | None = None,
    h: float | None = None,
    n_proposal: int | None = None,
) -> LikelihoodUpdate | None:
    """Weighted belief ``∝ q_{t-1} L_t`` (weighted points), or None if ``L_t = 0`` there.

    The ``m`` proposals are kept with their weights (no reduction to ``n_l`` in between, which
    would throw away diversity at every movement); resample with
    :func:`pipeline.resample.systematic_resample` for an equally weighted set.

    Plain proposal: the KDE ``q^`` of the belief, weights ``L_t``. When its effective sample
    size ``(sum w)^2 / sum w^2`` is below ``n_l`` (e.g. a wide belief, a narrow likelihood in
    its tail) and ``new_fl`` is given, ``m_d = min(m, DEFENSIVE_DRAWS)`` more draws come from
    the defensive mixture: half from ``q^`` (the belief resampled to ``n_l`` equal kernels, so
    its density is cheap), half from the KDE ``p^`` of this movement's own set ``p_t``, which
    covers where ``L_t > 0``;
    weights ``q^(x) L_t(x) / (q^(x) / 2 + p^(x) / 2)`` in the log domain (the target stays
    ``q^ L_t``: the prior of ``p_t`` is not counted). Both weighted sets are returned
    together (``m + m_d`` points), each scaled to total its effective sample size; only the
    defensive one if the plain one has no positive weight, only the plain one if the
    defensive one has none.

    Parameters
    ----------
    prev_fl : ndarray (n, 2)
        Previous belief ``q_{t-1}`` (FL).
    likelihood : callable
        Points (m, 2) FL -> (m,) non-negative (an unbiased estimate is enough).
    n_l : int
        Particles of the belief; ``m`` defaults to ``PROPOSALS_PER_PARTICLE * n_l``; the
        defensive proposal is used below an effective sample size of ``n_l``.
    rng : numpy.random.Generator
    prev_weights : ndarray (n,), optional
        Weights of ``prev_fl`` (default equal).
    new_fl : ndarray (k, 2), optional
        This movement's FL set ``p_t`` of the landmark (enables the defensive proposal).
    h : float, optional
        KDE bandwidth factor (default Scott of the effective sample size).
    n_proposal : int, optional
        Proposal draws ``m``.
    """
    m = PROPOSALS_PER_PARTICLE * n_l if n_proposal is None else n_proposal
    x = Kde.fit(prev_fl, h, weights=prev_weights).sample(m, rng)
    w = likelihood(x)
    plain = LikelihoodUpdate(x, w, defensive=False) if float(w.sum()) > 0.0 else None
    if new_fl is None or _ess(w) >= n_l:
        return plain
    kernels = prev_fl
    if prev_weights is not None or prev_fl.shape[0] != n_l:
        kept = np.ones(prev_fl.shape[0]) if prev_weights is None else prev_weights
        kernels = prev_fl[systematic_resample(kept, n_l, rng)]
    q_hat, p_hat = Kde.fit(kernels, h), Kde.fit(new_fl, h)
    m_d = min(m, DEFENSIVE_DRAWS)
    xd = _mixture_sample(q_hat, p_hat, m_d, rng)
    lik = likelihood(xd)
    if not float(lik.sum()) > 0.0:
        return plain
    # the two densities only where L_t > 0 (elsewhere the weight is 0 whatever they are): the
    # costly part, m_d x n_l kernel terms each, shrinks to the draws the likelihood keeps
    hit = np.flatnonzero(lik)
    lq, _, log_mix = _mixture_logpdf(q_hat, p_hat, xd[_padded(hit)], m_d)
    lq, log_mix = lq[: hit.size], log_mix[: hit.size]
    log_w = np.log(lik[hit])
    log_w += lq
    log_w -= log_mix
    log_w -= log_w.max()
    wd = np.zeros(m_d)
    wd[hit] = np.exp(log_w)
    if plain is None:
        return LikelihoodUpdate(xd, wd, defensive=True)
    # both sets, each scaled to total its effective sample size: inverse-variance weights of
    # two self-normalised estimates (ESS_i / sum w_i = sum w_i / sum w_i^2)
    w *= float(w.sum()) / float(w @ w)
    wd *= float(wd.sum()) / float(wd @ wd)
    return LikelihoodUpdate(np.vstack((x, xd)), np.concatenate((w, wd)), defensive=True)
