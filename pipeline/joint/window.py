"""Old keyframes folded into one linear prior, so that the joint map's graph stops growing.

Marginalizing variables out of a factor graph at the current estimate: the factors that touch
them (with the prior of earlier marginalizations) are linearized there, the variables are
eliminated, and what remains on their neighbours (the landmarks, the map's scale, the first
keyframe kept) becomes one Gaussian factor, kept as a GTSAM ``LinearContainerFactor`` at its
linearization point. Its information no longer changes with the estimate: the old keyframes'
bearings are not relinearized, re-weighted by a new noise estimate or re-judged as outliers.
The keyframes that leave the graph keep the pose and covariance they had then, their bearings
the residual they had then (:class:`FrozenBearings`).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

import gtsam
import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class Marginalized:
    """Variables marginalized out of a map.

    Attributes
    ----------
    prior : NonlinearFactor or None
        What their factors say about the remaining variables: one ``LinearContainerFactor`` on
        the neighbours of the old variables, at their values then (None: no neighbour).
    covariances : dict key -> (d, d) array
        Each old variable's marginal covariance in the whole map (its tangent space); empty when
        the old variables are not determined given their neighbours.
    """

    prior: gtsam.NonlinearFactor | None
    covariances: dict[int, NDArray[np.float64]]


def marginalize(
    factors: Iterable[gtsam.NonlinearFactor],
    values: gtsam.Values,
    old_keys: Sequence[int],
    joint_covariance: Callable[[list[int]], NDArray[np.float64]] | None = None,
) -> Marginalized:
    """Marginalize ``old_keys`` out of a map at ``values``.

    Parameters
    ----------
    factors : iterable of NonlinearFactor
        Every factor of the map that involves an old key; any other given joins the prior.
    values : gtsam.Values
        The linearization point; holds every key of ``factors``.
    old_keys : sequence of int
        The variables to marginalize out.
    joint_covariance : callable, optional
        The whole map's joint marginal covariance of the given keys (blocks in their order);
        without it no covariance is computed. The old variables' covariances are their
        conditional covariance given their neighbours (from ``factors``: no other factor
        involves them) plus the neighbours' own, propagated.
    """
    graph = gtsam.NonlinearFactorGraph()
    for factor in factors:
        graph.add(factor)
    linear = graph.linearize(values)
    present = set(graph.keyVector())
    old = [k for k in old_keys if k in present]
    others = sorted(present - set(old))
    if not old:
        return Marginalized(_container(linear, values), {})
    _, rest = linear.eliminatePartialSequential(gtsam.Ordering(old))
    if joint_covariance is None:
        return Marginalized(_container(rest, values), {})
    dims = values.dims()
    hessian, _ = linear.hessian(gtsam.Ordering([*old, *others]))
    n_old = sum(dims[k] for k in old)
    neighbours = joint_covariance(others) if others else np.zeros((0, 0))
    try:
        covs = _old_covariances(
            hessian[:n_old, :n_old], hessian[:n_old, n_old:], [dims[k] for k in old], neighbours
        )
    except np.linalg.LinAlgError:  # the old variables are not determined by their neighbours
        return Marginalized(_container(rest, values), {})
    return Marginalized(_container(rest, values), dict(zip(old, covs, strict=True)))


def _old_covariances(
    h_oo: NDArray[np.float64],
    h_os: NDArray[np.float64],
    sizes: list[int],
    neighbours: NDArray[np.float64],
) -> list[NDArray[np.float64]]:
    """The diagonal blocks of ``X + B S B^T``, ``X = h_oo^-1``, ``B = X h_os``, ``S`` the
    neighbours' covariance: each old variable's covariance. When ``h_oo`` is block tridiagonal
    (a chain of keyframes, in order) its blocks come from one pass down the chain and one back
    (no dense inverse: its cost grows with the chain, not its cube); otherwise densely."""
    cuts = np.cumsum([0, *sizes])
    blocks = [slice(int(a), int(b)) for a, b in itertools.pairwise(cuts)]
    n = len(blocks)
    if any(np.any(h_oo[blocks[i], int(cuts[i + 2]) :]) for i in range(n - 2)):
        x = np.linalg.inv(h_oo)
        gain = x @ h_os
        return [_symmetric(x[b, b] + gain[b] @ neighbours @ gain[b].T) for b in blocks]
    s_inv: list[NDArray[np.float64]] = []
    rhs: list[NDArray[np.float64]] = []
    for i, b in enumerate(blocks):
        d, f = h_oo[b, b], h_os[b]
        if i:
            e = h_oo[blocks[i - 1], b]
            k = e.T @ s_inv[-1]
            d, f = d - k @ e, f - k @ rhs[-1]
        s_inv.append(np.asarray(np.linalg.inv(d), np.float64))
        rhs.append(f)
    out: list[NDArray[np.float64]] = []
    x_next = gain_next = np.zeros((0, 0))
    for i in reversed(range(n)):
        si = s_inv[i]
        if i == n - 1:
            x, gain = si, si @ rhs[i]
        else:
            e = h_oo[blocks[i], blocks[i + 1]]
            k = si @ e
            x, gain = si + k @ x_next @ k.T, si @ (rhs[i] - e @ gain_next)
        out.append(_symmetric(x + gain @ neighbours @ gain.T))
        x_next, gain_next = x, gain
    return out[::-1]


def _symmetric(m: NDArray[np.float64]) -> NDArray[np.float64]:
    return 0.5 * (m + m.T)


def _container(
    linear: gtsam.GaussianFactorGraph, values: gtsam.Values
) -> gtsam.NonlinearFactor | None:
    """The non-empty factors of ``linear`` as one factor at ``values`` (None: no factor)."""
    kept = gtsam.GaussianFactorGraph()
    for i in range(linear.size()):
        f = linear.at(i)
        if f is not None and not f.empty():
            kept.push_back(f)
    keys = list(kept.keyVector())
    if not keys:
        return None
    return gtsam.LinearContainerFactor(gtsam.HessianFactor(kept), values.extract(keys))


@dataclass(frozen=True)
class FrozenBearings:
    """Bearings of keyframes no longer in the graph, with the residual each had when its
    keyframe left: landmark catalog index, residual (rad) and whether it was rejected, (n,) each.
    """

    landmark: NDArray[np.int64]
    residual_rad: NDArray[np.float64]
    rejected: NDArray[np.bool_]

    @staticmethod
    def empty() -> FrozenBearings:
        """No bearings."""
        return FrozenBearings(np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.bool_))

    def plus(
        self,
        landmark: NDArray[np.int64],
        residual_rad: NDArray[np.float64],
        rejected: NDArray[np.bool_],
    ) -> FrozenBearings:
        """These bearings and more (a new object)."""
        return FrozenBearings(
            np.concatenate([self.landmark, landmark]),
            np.concatenate([self.residual_rad, residual_rad]),
            np.concatenate([self.rejected, rejected]),
        )

    def without(self, landmark: int) -> FrozenBearings:
        """These bearings less those of one landmark (a new object)."""
        keep = self.landmark != landmark
        return FrozenBearings(self.landmark[keep], self.residual_rad[keep], self.rejected[keep])

    def __len__(self) -> int:
        return int(self.landmark.size)
