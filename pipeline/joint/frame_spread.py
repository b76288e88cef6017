"""A landmark's covariance in FL with the frame's turn and scale carried to second order.

FL is fixed on the reference pair (L1 = (0, 0), L2 = (1, 0)). When the rest of the map sees the
pair's direction or length wrongly, every other landmark turns and scales about the pair
together: a far landmark's error lies on an arc about the pair, where the linearized (x, y)
covariance stands for its tangent line only. A thin ellipse along the tangent then misses
truths that lie a little off it, on the arc.

In polar coordinates about the pair's midpoint, ``u = log distance`` and ``phi = direction``, a
turn and a scaling of the frame add to ``(u, phi)``: there the error is linear. So
:func:`frame_spread_cov` carries the map's linearized covariance into ``(u, phi)`` (the same
covariance to first order) and returns the second moment about the estimate of that Gaussian
mapped back to x, y, in closed form: for a Gaussian ``X ~ N(m, S)`` and complex ``t``,
``E exp(t'X) = exp(t'm + t'S t / 2)``, so with ``w = exp(u + i phi)`` (the landmark as a complex
number about the midpoint) ``E w``, ``E w^2`` and ``E |w|^2`` are exponentials of the moments.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

#: The pole of the polar coordinates: the reference pair's midpoint (FL).
PIVOT_FL = (0.5, 0.0)
#: The polar form is used only when the pole lies at least this many standard deviations (of
#: the landmark's larger axis) from the estimate; nearer, a direction about the pole means
#: little and the linearized covariance is kept.
PIVOT_CLEARANCE_STD = 3.0


def frame_spread_cov(
    mean_fl: NDArray[np.float64], cov_fl: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Second moment (2, 2) FL^2 about ``mean_fl`` (2,) FL of the landmark whose linearized
    covariance is ``cov_fl`` (2, 2) FL^2, with the error taken as Gaussian in (log distance,
    direction) about :data:`PIVOT_FL` rather than in (x, y).

    Equal to ``cov_fl`` to first order. For a landmark far from the pair with a wide direction,
    wider along the direction from the pair by about the arc's sag, and a little narrower across
    it (the arc's chord is shorter than the arc). ``cov_fl`` itself when the pole is within
    :data:`PIVOT_CLEARANCE_STD` standard deviations, or ``cov_fl`` is not a finite positive
    definite matrix.
    """
    cov = np.asarray(cov_fl, np.float64)
    z = np.asarray(mean_fl, np.float64) - np.asarray(PIVOT_FL)
    rho = math.hypot(float(z[0]), float(z[1]))
    if not (np.isfinite(cov).all() and np.isfinite(z).all()):
        return cov
    eig = np.linalg.eigvalsh(cov)
    if eig[0] <= 0.0 or rho <= PIVOT_CLEARANCE_STD * math.sqrt(eig[-1]):
        return cov
    # d(x, y) = [[x, -y], [y, x]] d(u, phi): the covariance of (u, phi)
    x, y = float(z[0]), float(z[1])
    to_polar = np.array([[x, y], [-y, x]]) / (rho * rho)
    s = to_polar @ cov @ to_polar.T
    s_uu, s_up, s_pp = float(s[0, 0]), float(s[0, 1]), float(s[1, 1])
    w0 = complex(x, y)
    # E w, E w^2, E |w|^2 for (u, phi) ~ N((log rho, arg z), s)
    e_w = w0 * np.exp(0.5 * (s_uu - s_pp) + 1j * s_up)
    e_w2 = w0 * w0 * np.exp(2.0 * (s_uu - s_pp) + 4j * s_up)
    e_abs2 = rho * rho * math.exp(2.0 * s_uu)
    second = 0.5 * np.array(
        [[e_abs2 + e_w2.real, e_w2.imag], [e_w2.imag, e_abs2 - e_w2.real]], np.float64
    )
    first = np.array([e_w.real, e_w.imag])
    out = second - np.outer(z, first) - np.outer(first, z) + np.outer(z, z)
    return 0.5 * (out + out.T)
