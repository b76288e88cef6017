"""Point estimate and credible region of a landmark from its particle set (FL)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


def chi2_2dof_quantile(p: float) -> float:
    """Quantile of the chi-square law with 2 degrees of freedom: ``-2 log(1 - p)``."""
    return -2.0 * math.log1p(-p)


@dataclass(frozen=True, eq=False)
class LandmarkEstimate:
    """Mean and covariance of a landmark in FL, with a Gaussian credible ellipse.

    Attributes
    ----------
    mean_fl : ndarray (2,)
        Particle mean (FL, unit |L1 L2|).
    cov_fl : ndarray (2, 2)
        Particle covariance.
    """

    mean_fl: NDArray[np.float64]
    cov_fl: NDArray[np.float64]

    @classmethod
    def from_particles(
        cls, particles_fl: NDArray[np.float64], *, weights: NDArray[np.float64] | None = None
    ) -> LandmarkEstimate:
        """Estimate from a particle set (n, 2) FL, equally weighted or with ``weights`` (n,).

        Weighted: the covariance is divided by ``1 - sum w^2`` (``w`` normalised), which is
        ``(n - 1) / n`` for equal weights (the unbiased sample covariance).
        """
        x = np.asarray(particles_fl, dtype=np.float64)
        n = x.shape[0]
        w = np.full(n, 1.0 / n) if weights is None else weights / weights.sum()
        d = np.array(x.T, order="C")  # (2, n) copy: long contiguous rows (numpy is slow on (n, 2))
        mean = d @ w
        d -= mean[:, None]
        return cls(mean, ((d * w) @ d.T) / max(1.0 - float(w @ w), 1e-12))

    def mahalanobis2(self, point_fl: NDArray[np.float64]) -> float:
        """Squared Mahalanobis distance of a point (2,) from the mean."""
        d = np.asarray(point_fl, dtype=np.float64) - self.mean_fl
        vals, vecs = np.linalg.eigh(self.cov_fl)
        proj2 = (vecs.T @ d) ** 2
        if np.any((vals <= 0.0) & (proj2 > 0.0)):
            return math.inf  # off a degenerate (zero-width) belief
        return float(np.sum(np.where(vals > 0.0, proj2 / np.where(vals > 0.0, vals, 1.0), 0.0)))

    def contains(self, point_fl: NDArray[np.float64], p: float = 0.8) -> bool:
        """Whether a point (2,) FL lies in the ``p`` credible ellipse."""
        return self.mahalanobis2(point_fl) <= chi2_2dof_quantile(p)

    def credible_ellipse(self, p: float = 0.8, n: int = 64) -> NDArray[np.float64]:
        """The ``p`` credible ellipse as a polygon (n, 2) in FL."""
        vals, vecs = np.linalg.eigh(self.cov_fl)
        radii = np.sqrt(np.maximum(vals, 0.0) * chi2_2dof_quantile(p))
        t = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
        circle = np.column_stack((np.cos(t), np.sin(t))) * radii
        out: NDArray[np.float64] = self.mean_fl + circle @ vecs.T
        return out
