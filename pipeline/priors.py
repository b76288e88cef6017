"""Single-bearing priors: the impartial PDF and the two baselines it is compared with.

All three share one interface (:class:`Prior`): a density per unit area over the plane, given
an observation point ``origin`` (2,) and a measured bearing ``bearing_rad`` (the direction of the
ray in the frame of ``origin``'s coordinates), and sampling. Units are those of the frame (FR:
movement length = 1).

* :class:`ImpartialPrior` (docs/method.md, part 2): ``p(r, a) = g(a) / ((r_max - r_min) r)`` on the
  vision cone ``|a - bearing| <= eps``, ``r_min <= r <= r_max``; its range marginal is uniform.
* :class:`GaussianPrior`: one 2-D Gaussian on the ray, centred at ``(r_min + r_max) / 2`` with
  range std ``(r_max - r_min) / 4`` and cross-range std ``r0 * sigma_a``.
* :class:`MixturePrior`: undelayed initialization in the style of Solà et al. (2005): a
  geometric series of equally weighted Gaussians along the ray, means ``s_j = s_0 beta^j`` with
  ``s_0 = r_min / (1 - alpha)``, range std ``alpha s_j``, cross-range std ``s_j sigma_a``, ratio
  ``beta = (1 + alpha) / (1 - alpha)`` (neighbouring 1-sigma intervals touch), as many terms as
  needed for ``s_j (1 + alpha) >= r_max``. Default ``alpha = 0.3``.

``g`` (the angular density) is a Gaussian of std ``sigma_a = sigma_frac * eps`` truncated to
``[-eps, eps]`` (default ``sigma_frac = 0.5``) or uniform on ``[-eps, eps]``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cache
from typing import Literal, Protocol

import numpy as np
from numpy.typing import NDArray

from data_schemas.errors import EstimationError

PriorName = Literal["impartial", "gaussian", "mixture"]
AngularKind = Literal["gaussian", "uniform"]

#: Default range bounds in FR units (movement length = 1). Landmarks closer than a tenth of a
#: movement are inside the robot's body for the paper's geometry; 20 movements is beyond any
#: landmark of a 1.05 x 0.68 m arena seen from moves of >= 0.06 m.
R_MIN_FR = 0.1
R_MAX_FR = 20.0

#: Points per block in :meth:`ImpartialPrior.density` (temporaries of 64 KiB).
BLOCK = 8192


class Prior(Protocol):
    """What every single-bearing prior provides."""

    @property
    def eps_rad(self) -> float:
        """Bound on the bearing error (rad)."""
        ...

    @property
    def r_min(self) -> float:
        """Smallest range (frame units)."""
        ...

    @property
    def r_max(self) -> float:
        """Largest range (frame units)."""
        ...

    def density(
        self, points: NDArray[np.float64], origin: NDArray[np.float64], bearing_rad: float
    ) -> NDArray[np.float64]:
        """Density per unit area at ``points`` (n, 2); returns (n,)."""
        ...

    def sample(
        self, n: int, origin: NDArray[np.float64], bearing_rad: float, rng: np.random.Generator
    ) -> NDArray[np.float64]:
        """``n`` points (n, 2) drawn from the prior."""
        ...

    def angle_window(self, bearing_rad: float) -> tuple[float, float]:
        """Angles (lo, hi) outside which the density is zero (or negligible)."""
        ...


def _check(eps_rad: float, r_min: float, r_max: float) -> None:
    if not 0.0 < eps_rad < math.pi / 2:
        raise EstimationError(f"vision error eps must be in (0, 90) deg, got {eps_rad} rad")
    if not 0.0 < r_min < r_max or not math.isfinite(r_max):
        raise EstimationError(f"need 0 < r_min < r_max < inf, got r_min={r_min}, r_max={r_max}")


@dataclass(frozen=True)
class ImpartialPrior:
    """The impartial PDF of one bearing (uniform range marginal).

    Parameters
    ----------
    eps_rad : float
        Bound on the bearing error (rad).
    r_min, r_max : float
        Range bounds (frame units).
    angular : {"gaussian", "uniform"}
        Shape of ``g`` on ``[-eps, eps]``.
    sigma_frac : float
        Std of the Gaussian ``g`` as a fraction of ``eps``.
    """

    eps_rad: float
    r_min: float = R_MIN_FR
    r_max: float = R_MAX_FR
    angular: AngularKind = "gaussian"
    sigma_frac: float = 0.5
    _norm: float = field(init=False, repr=False)

    def __post_init__(self) -> None:
        _check(self.eps_rad, self.r_min, self.r_max)
        if self.angular == "gaussian":
            k = 1.0 / self.sigma_frac
            mass = math.erf(k / math.sqrt(2.0))
            norm = 1.0 / (self.sigma_frac * self.eps_rad * math.sqrt(2.0 * math.pi) * mass)
        else:
            norm = 1.0 / (2.0 * self.eps_rad)
        object.__setattr__(self, "_norm", norm / (self.r_max - self.r_min))

    def g(self, da_rad: NDArray[np.float64]) -> NDArray[np.float64]:
        """Angular density ``g`` at offsets ``da_rad`` from the bearing (zero outside eps)."""
        da = np.asarray(da_rad, dtype=np.float64)
        inside = np.abs(da) <= self.eps_rad
        scale = self._norm * (self.r_max - self.r_min)
        if self.angular == "gaussian":
            s = self.sigma_frac * self.eps_rad
            return np.where(inside, scale * np.exp(-0.5 / (s * s) * da * da), 0.0)
        return np.where(inside, scale, 0.0)

    def g_product(
        self, da1_rad: NDArray[np.float64], da2_rad: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """``g(da1) g(da2)`` elementwise (one exponential): the likelihood of two bearings."""
        sq1 = da1_rad * da1_rad
        sq2 = da2_rad * da2_rad
        inside = np.maximum(sq1, sq2) <= self.eps_rad * self.eps_rad
        scale = (self._norm * (self.r_max - self.r_min)) ** 2
        if self.angular == "gaussian":
            sq1 += sq2
            sq1 *= -0.5 / (self.sigma_frac * self.eps_rad) ** 2
            out: NDArray[np.float64] = np.exp(sq1, out=sq1)
            out *= inside
            out *= scale
            return out
        return np.where(inside, scale, 0.0)

    def density(
        self, points: NDArray[np.float64], origin: NDArray[np.float64], bearing_rad: float
    ) -> NDArray[np.float64]:
        """``g(a) / ((r_max - r_min) r)`` inside the cone, 0 outside; points (n, 2) -> (n,).

        Works in blocks of ``BLOCK`` points so that every temporary stays in the allocator's
        heap and the cache (fresh large arrays cost page faults: half the time at 100k points).
        """
        p = np.asarray(points, dtype=np.float64)
        c, s = math.cos(bearing_rad), math.sin(bearing_rad)
        ox, oy = float(origin[0]), float(origin[1])
        a0, x0 = ox * c + oy * s, oy * c - ox * s  # the origin in the ray's frame
        tan_eps = math.tan(self.eps_rad)
        lo2, hi2 = self.r_min**2, self.r_max**2
        k = -0.5 / (self.sigma_frac * self.eps_rad) ** 2
        out = np.empty(p.shape[0])
        for start in range(0, p.shape[0], BLOCK):
            blk = p[start : start + BLOCK]
            along = blk[:, 0] * c
            along += blk[:, 1] * s
            along -= a0
            across = blk[:, 1] * c
            across -= blk[:, 0] * s
            across -= x0
            # cheap cone test on every point, the rest only inside the wedge
            idx = np.flatnonzero(np.abs(across) <= tan_eps * along)
            a_in = along[idx]
            x_in = across[idx]
            r2 = a_in * a_in
            r2 += x_in * x_in
            val = np.zeros(idx.size)
            keep = np.flatnonzero((r2 >= lo2) & (r2 <= hi2))
            r_in = np.sqrt(r2[keep])
            if self.angular == "gaussian":
                da = np.arctan(x_in[keep] / a_in[keep])
                da *= da
                da *= k
                val[keep] = np.exp(da, out=da) / r_in
            else:
                val[keep] = 1.0 / r_in
            res = out[start : start + BLOCK]
            res[:] = 0.0
            res[idx] = val * self._norm
        return out

    def sample_angle(self, n: int, rng: np.random.Generator) -> NDArray[np.float64]:
        """``n`` angular offsets drawn from ``g`` (rad)."""
        if self.angular == "uniform":
            return rng.uniform(-self.eps_rad, self.eps_rad, n)
        # Exact truncated normal by rejection (no scipy.special import: ~0.14 s); acceptance is
        # P(|z| <= 1 / sigma_frac), 95% at the default sigma = eps / 2.
        k = 1.0 / self.sigma_frac
        out = np.empty(n)
        filled = 0
        while filled < n:
            z = rng.standard_normal(int((n - filled) * 1.1) + 8)
            z = z[np.abs(z) <= k][: n - filled]
            out[filled : filled + z.size] = z
            filled += z.size
        out *= self.sigma_frac * self.eps_rad
        return out

    def sample(
        self, n: int, origin: NDArray[np.float64], bearing_rad: float, rng: np.random.Generator
    ) -> NDArray[np.float64]:
        """``r ~ U[r_min, r_max]``, ``a ~ g``: points (n, 2)."""
        r = rng.uniform(self.r_min, self.r_max, n)
        a = bearing_rad + self.sample_angle(n, rng)
        return np.column_stack((origin[0] + r * np.cos(a), origin[1] + r * np.sin(a)))

    def angle_window(self, bearing_rad: float) -> tuple[float, float]:
        """The cone's angles."""
        return bearing_rad - self.eps_rad, bearing_rad + self.eps_rad


def _gauss_ray_density(
    points: NDArray[np.float64],
    origin: NDArray[np.float64],
    bearing_rad: float,
    means: NDArray[np.float64],
    std_along: NDArray[np.float64],
    std_across: NDArray[np.float64],
    weights: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Mixture of axis-aligned (along/across the ray) Gaussians; points (n, 2) -> (n,)."""
    p = np.asarray(points, dtype=np.float64)
    c, s = math.cos(bearing_rad), math.sin(bearing_rad)
    dx = p[:, 0] - origin[0]
    dy = p[:, 1] - origin[1]
    along = (dx * c + dy * s)[:, None]
    across = (dy * c - dx * s)[:, None]
    za = (along - means) / std_along
    zc = across / std_across
    coef = weights / (2.0 * math.pi * std_along * std_across)
    out: NDArray[np.float64] = np.exp(-0.5 * (za * za + zc * zc)) @ coef
    return out


def _gauss_ray_sample(
    n: int,
    origin: NDArray[np.float64],
    bearing_rad: float,
    means: NDArray[np.float64],
    std_along: NDArray[np.float64],
    std_across: NDArray[np.float64],
    weights: NDArray[np.float64],
    rng: np.random.Generator,
) -> NDArray[np.float64]:
    j = rng.choice(means.size, size=n, p=weights)
    along = means[j] + std_along[j] * rng.standard_normal(n)
    across = std_across[j] * rng.standard_normal(n)
    c, s = math.cos(bearing_rad), math.sin(bearing_rad)
    return np.column_stack((origin[0] + along * c - across * s, origin[1] + along * s + across * c))


class _GaussiansOnRay:
    """Density, sampling and angular window of equally shaped Gaussians laid along the ray.

    Subclasses give ``_params()``: per term, the range of its mean, its range std, its cross std
    and its weight (the baselines of Fig. 1: one term, or a Solà-style series).
    """

    def _params(
        self,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        raise NotImplementedError

    def density(
        self, points: NDArray[np.float64], origin: NDArray[np.float64], bearing_rad: float
    ) -> NDArray[np.float64]:
        """Density per unit area at points (n, 2) -> (n,)."""
        return _gauss_ray_density(points, origin, bearing_rad, *self._params())

    def sample(
        self, n: int, origin: NDArray[np.float64], bearing_rad: float, rng: np.random.Generator
    ) -> NDArray[np.float64]:
        """Points (n, 2) drawn from the density."""
        return _gauss_ray_sample(n, origin, bearing_rad, *self._params(), rng)

    def angle_window(self, bearing_rad: float) -> tuple[float, float]:
        """The whole circle (the first term covers the origin)."""
        return bearing_rad - math.pi, bearing_rad + math.pi


@dataclass(frozen=True)
class GaussianPrior(_GaussiansOnRay):
    """Baseline: one Gaussian on the ray (range std (r_max - r_min)/4, centred mid-range)."""

    eps_rad: float
    r_min: float = R_MIN_FR
    r_max: float = R_MAX_FR
    sigma_frac: float = 0.5

    def __post_init__(self) -> None:
        _check(self.eps_rad, self.r_min, self.r_max)

    def _params(
        self,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        r0 = 0.5 * (self.r_min + self.r_max)
        return (
            np.array([r0]),
            np.array([(self.r_max - self.r_min) / 4.0]),
            np.array([r0 * self.sigma_frac * self.eps_rad]),
            np.array([1.0]),
        )


@dataclass(frozen=True)
class MixturePrior(_GaussiansOnRay):
    """Baseline: Solà-style geometric series of equally weighted Gaussians along the ray."""

    eps_rad: float
    r_min: float = R_MIN_FR
    r_max: float = R_MAX_FR
    sigma_frac: float = 0.5
    alpha: float = 0.3

    def __post_init__(self) -> None:
        _check(self.eps_rad, self.r_min, self.r_max)
        if not 0.0 < self.alpha < 1.0:
            raise EstimationError(f"mixture alpha must be in (0, 1), got {self.alpha}")

    def means(self) -> NDArray[np.float64]:
        """Range of each term's mean (frame units)."""
        beta = (1.0 + self.alpha) / (1.0 - self.alpha)
        s0 = self.r_min / (1.0 - self.alpha)
        n = max(1, math.ceil(math.log(self.r_max / (s0 * (1.0 + self.alpha))) / math.log(beta)) + 1)
        out: NDArray[np.float64] = s0 * beta ** np.arange(n, dtype=np.float64)
        return out

    def _params(
        self,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        s = self.means()
        return s, self.alpha * s, self.sigma_frac * self.eps_rad * s, np.full(s.size, 1.0 / s.size)


def make_prior(
    name: PriorName,
    eps_rad: float,
    r_min: float = R_MIN_FR,
    r_max: float = R_MAX_FR,
    *,
    angular: AngularKind = "gaussian",
    sigma_frac: float = 0.5,
) -> Prior:
    """Build a prior by name (``"impartial"``, ``"gaussian"`` or ``"mixture"``).

    ``sigma_frac``: angular std as a fraction of ``eps`` (all three priors).
    """
    if name == "impartial":
        return ImpartialPrior(eps_rad, r_min, r_max, angular=angular, sigma_frac=sigma_frac)
    if name == "gaussian":
        return GaussianPrior(eps_rad, r_min, r_max, sigma_frac=sigma_frac)
    if name == "mixture":
        return MixturePrior(eps_rad, r_min, r_max, sigma_frac=sigma_frac)
    raise EstimationError(f"unknown prior {name!r}; use 'impartial', 'gaussian' or 'mixture'")


def prior_density_grid(
    prior: PriorName | Prior,
    bearing_rad: float,
    eps_rad: float,
    r_min: float,
    r_max: float,
    xs: NDArray[np.float64],
    ys: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Density of one bearing seen from (0, 0) on the grid ``xs`` x ``ys`` (the paper's Fig. 1).

    Returns
    -------
    ndarray (len(ys), len(xs))
        Density per unit area; row i is ``y = ys[i]``.
    """
    pr = make_prior(prior, eps_rad, r_min, r_max) if isinstance(prior, str) else prior
    gx, gy = np.meshgrid(np.asarray(xs, float), np.asarray(ys, float))
    pts = np.column_stack((gx.ravel(), gy.ravel()))
    return pr.density(pts, np.zeros(2), bearing_rad).reshape(gx.shape)


@cache
def _gauss_legendre(n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Gauss-Legendre nodes (ascending) and weights on [-1, 1], n >= 1.

    Newton's method on the Legendre polynomial P_n from Tricomi's initial guesses, all nodes at
    once: O(n^2) per step (numpy's ``leggauss`` solves a dense n x n eigenproblem, seconds at
    n = 2048; scipy's ``roots_legendre`` costs importing ``scipy.special``, ~0.5 s).
    """
    x = np.cos(np.pi * (np.arange(1, n + 1) - 0.25) / (n + 0.5))
    for _ in range(100):
        p_n, dp_n = _legendre_and_derivative(n, x)
        step = p_n / dp_n
        x = x - step
        if float(np.max(np.abs(step))) < 1e-14:
            break
    _, dp_n = _legendre_and_derivative(n, x)
    w = 2.0 / ((1.0 - x * x) * dp_n * dp_n)
    return x[::-1].copy(), w[::-1].copy()


def _legendre_and_derivative(
    n: int, x: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """P_n(x) and P_n'(x) by Bonnet's recurrence; x (m,) strictly inside (-1, 1)."""
    p_prev, p = np.ones_like(x), x.copy()
    for j in range(2, n + 1):
        p_prev, p = p, ((2 * j - 1) * x * p - (j - 1) * p_prev) / j
    dp = n * (x * p - p_prev) / (x * x - 1.0)
    return p, dp


def range_marginal(
    prior: Prior, r: NDArray[np.float64], bearing_rad: float = 0.0, n_angle: int = 2048
) -> NDArray[np.float64]:
    """Range marginal ``p(r) = ∫ p(r, a) r da`` by Gauss-Legendre quadrature over the angle.

    Parameters
    ----------
    prior : Prior
    r : ndarray (k,)
        Ranges from the observation point.
    bearing_rad : float
    n_angle : int
        Quadrature nodes over ``prior.angle_window``.

    Returns
    -------
    ndarray (k,)
        Density of the range (per unit range).
    """
    lo, hi = prior.angle_window(bearing_rad)
    x, w = _gauss_legendre(n_angle)
    a = 0.5 * (hi - lo) * x + 0.5 * (hi + lo)
    w = 0.5 * (hi - lo) * w
    rr = np.asarray(r, dtype=np.float64)
    pts = np.column_stack(
        (np.outer(rr, np.cos(a)).ravel(), np.outer(rr, np.sin(a)).ravel())
    )  # (k * n_angle, 2)
    dens = prior.density(pts, np.zeros(2), bearing_rad).reshape(rr.size, a.size)
    out: NDArray[np.float64] = (dens @ w) * rr
    return out


__all__ = [
    "R_MAX_FR",
    "R_MIN_FR",
    "GaussianPrior",
    "ImpartialPrior",
    "MixturePrior",
    "Prior",
    "make_prior",
    "prior_density_grid",
    "range_marginal",
]
