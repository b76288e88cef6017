"""Recursive fusion in FL: ``q_t = q_{t-1} p_t / ∫ q_{t-1} p_t`` (METHOD.md section 5).

Both particle sets are turned into densities by a Gaussian kernel density estimate with Liu &
West (2001) shrinkage: kernel centres ``a x_i + (1 - a) mean``, kernel covariance ``h^2 Cov``,
``a = sqrt(1 - h^2)``, so the KDE keeps the set's mean and covariance exactly (a plain KDE would
inflate the covariance by ``1 + h^2`` at every fusion step). ``h`` defaults to Scott's factor
``n^(-1/6)`` (2-D).

Proposal: the defensive mixture ``(q^ + p^) / 2`` (half the draws from each KDE), which covers
the product's support wherever either belief has mass. Importance weights
``q^(x) p^(x) / ((q^(x) + p^(x)) / 2)`` are computed in the log domain, then one systematic
resampling to ``n_l`` particles.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pipeline.resample import systematic_resample


@dataclass(frozen=True)
class Kde:
    """Shrinkage Gaussian KDE of a 2-D particle set (frame of the particles).

    Attributes
    ----------
    centres_w : ndarray (n, 2)
        Kernel centres in whitened coordinates (kernel covariance = identity).
    whiten : ndarray (2, 2)
        ``W`` with ``W x`` whitened (``W^T W = (h^2 Cov)^-1``).
    chol : ndarray (2, 2)
        Lower Cholesky factor of the kernel covariance (for sampling).
    centres : ndarray (n, 2)
        Kernel centres in the original frame.
    log_norm : float
        ``-log(n) - log(2 pi) - log det(chol)``.
    """

    centres: NDArray[np.float64]
    centres_w: NDArray[np.float64]
    sq_w: NDArray[np.float64]
    whiten: NDArray[np.float64]
    chol: NDArray[np.float64]
    log_norm: float

    @classmethod
    def fit(cls, particles: NDArray[np.float64], h: float | None = None) -> Kde:
        """KDE of ``particles`` (n, 2) with bandwidth factor ``h`` (default Scott)."""
        x = np.asarray(particles, dtype=np.float64)
        n = x.shape[0]
        hh = n ** (-1.0 / 6.0) if h is None else h
        mean = x.mean(axis=0)
        d = x - mean
        cov = (d.T @ d) / max(n - 1, 1)
        ridge = 1e-12 * max(float(np.trace(cov)), 1e-12)
        cov = cov + ridge * np.eye(2)
        chol = np.linalg.cholesky(hh * hh * cov)
        whiten = np.linalg.inv(chol)
        a = math.sqrt(max(0.0, 1.0 - hh * hh))
        centres = a * x + (1.0 - a) * mean
        cw = centres @ whiten.T
        log_norm = -math.log(n) - math.log(2.0 * math.pi) - math.log(chol[0, 0] * chol[1, 1])
        return cls(centres, cw, (cw * cw).sum(axis=1), whiten, chol, log_norm)

    def logpdf(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """Log density at points (m, 2) -> (m,)."""
        qw = points @ self.whiten.T
        d2 = (qw * qw).sum(axis=1)[:, None] + self.sq_w[None, :] - 2.0 * (qw @ self.centres_w.T)
        # log-sum-exp over kernels, anchored at the nearest centre
        m = d2.min(axis=1)
        s = np.exp(-0.5 * (d2 - m[:, None])).sum(axis=1)
        out: NDArray[np.float64] = np.log(s) - 0.5 * m + self.log_norm
        return out

    def sample(self, n: int, rng: np.random.Generator) -> NDArray[np.float64]:
        """``n`` points (n, 2) from the KDE."""
        idx = rng.integers(0, self.centres.shape[0], n)
        out: NDArray[np.float64] = self.centres[idx] + rng.standard_normal((n, 2)) @ self.chol.T
        return out


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
    m = n_l if n_proposal is None else n_proposal
    m_q = m - m // 2
    m_p = m // 2
    x = np.vstack((q.sample(m_q, rng), p.sample(m_p, rng)))
    lq = q.logpdf(x)
    lp = p.logpdf(x)
    log_w = lq + lp - np.logaddexp(lq + math.log(m_q), lp + math.log(max(m_p, 1)))
    w = np.exp(log_w - log_w.max())
    return x[systematic_resample(w, n_l, rng)]
