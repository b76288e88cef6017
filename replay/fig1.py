"""The paper's Fig. 1 in Rerun: one bearing's density under the three priors.

The impartial PDF is uniform in range (density ~ 1/r across the cone); a single Gaussian along
the bearing and a Gaussian mixture along the ray (Solà et al.) are not. Each density is drawn as
a heat map over the cone (y stretched so the narrow cone is readable) under
``fig1/density/<prior>``, and its range marginal p(r) as a bar chart under ``fig1/range/<prior>``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache

import cv2
import numpy as np
import rerun as rr
from numpy.typing import NDArray

from pipeline.priors import make_prior, prior_density_grid, range_marginal
from replay.records import PRIORS

#: Range window of the figure, FR units (movement length = 1).
R_MIN, R_MAX = 0.1, 5.0
WIDTH, HEIGHT = 320, 160
#: Quadrature nodes over the cone for p(r) (the window is 2 eps wide: 64 is plenty, and
#: numpy's Gauss-Legendre nodes cost O(n^3)).
N_ANGLE = 64


@dataclass(frozen=True)
class Fig1:
    """The paper's Fig. 1 for one bearing: each prior's density on a grid and its p(r).

    Attributes
    ----------
    xs, ys : ndarray (nx,), (ny,)
        Grid of the densities, FR units (the bearing along +x from the origin).
    densities : dict of str to ndarray (ny, nx)
        Density of each prior (:data:`~replay.records.PRIORS`) at ``(xs[j], ys[i])``.
    r : ndarray (k,)
        Ranges of the marginals (bin centres: the support's ends would halve p(r)).
    marginals : dict of str to ndarray (k,)
        Range marginal p(r) of each prior.
    """

    xs: NDArray[np.float64]
    ys: NDArray[np.float64]
    densities: dict[str, NDArray[np.float64]]
    r: NDArray[np.float64]
    marginals: dict[str, NDArray[np.float64]]


@cache
def fig1_data(
    eps_rad: float, *, nx: int = WIDTH, ny: int = HEIGHT, nr: int = 60, bearing_rad: float = 0.0
) -> Fig1:
    """Compute Fig. 1 (every prior, the cone of ``eps_rad`` around ``bearing_rad``); ``ys``
    runs from +y to -y, as image rows do.

    Cached per arguments (one figure per log's eps, however many recordings a process makes);
    the arrays are shared, read-only.
    """
    half = R_MAX * math.tan(1.6 * eps_rad)
    xs = np.linspace(0.0, R_MAX, nx)
    ys = np.linspace(half, -half, ny)
    edges = np.linspace(R_MIN, R_MAX, nr + 1)
    r = 0.5 * (edges[1:] + edges[:-1])
    densities: dict[str, NDArray[np.float64]] = {}
    marginals: dict[str, NDArray[np.float64]] = {}
    for name in PRIORS:
        densities[name] = prior_density_grid(name, bearing_rad, eps_rad, R_MIN, R_MAX, xs, ys)
        prior = make_prior(name, eps_rad, R_MIN, R_MAX)
        marginals[name] = range_marginal(prior, r, bearing_rad, n_angle=N_ANGLE)
    for a in (xs, ys, r, *densities.values(), *marginals.values()):
        a.flags.writeable = False
    return Fig1(xs, ys, densities, r, marginals)


def log_fig1(rec: rr.RecordingStream, eps_rad: float, *, bearing_rad: float = 0.0) -> None:
    """Log the three priors' densities and range marginals for one bearing (static)."""
    fig = fig1_data(eps_rad, bearing_rad=bearing_rad)
    r = fig.r
    for name in PRIORS:
        density = fig.densities[name]
        scaled = np.sqrt(density / max(float(density.max()), 1e-300))
        heat = cv2.applyColorMap((255 * scaled).astype(np.uint8), cv2.COLORMAP_VIRIDIS)
        rec.log(f"fig1/density/{name}", rr.Image(heat, color_model="BGR"), static=True)
        marginal = fig.marginals[name]
        rec.log(
            f"fig1/range/{name}",
            rr.BarChart(marginal, abscissa=r, widths=np.full(r.size, r[1] - r[0])),
            static=True,
        )
