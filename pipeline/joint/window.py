"""Old keyframes folded into one linear prior, so that the joint map's graph stops growing.

Once the map holds :data:`WINDOW_STRIDE` movements more than its window, the oldest leave the
graph (:func:`marginalize_oldest`): the factors that touch their keyframes (with the prior of
earlier marginalizations) are linearized at the current estimate, the keyframes are eliminated,
and what remains on their neighbours (the landmarks, the map's scale, the first keyframe kept)
becomes one Gaussian factor, kept as a GTSAM ``LinearContainerFactor`` at its linearization
point (:func:`marginalize`). That information no longer changes with the estimate: the old
keyframes' bearings are not relinearized, re-weighted by a new noise estimate or re-judged as
outliers. The movements that leave keep the poses and covariances their keyframes had then
(:class:`pipeline.joint.state.FrozenMovement`), their bearings the residuals they had then
(:class:`pipeline.joint.state.FrozenBearings`).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

import gtsam
import numpy as np
from numpy.typing import NDArray

from pipeline.joint import graph as g
from pipeline.joint.mapgraph import CAREFUL_MOVEMENTS, MapGraph
from pipeline.joint.state import FrozenMovement, MapState

#: Movements the joint map keeps in its graph by default (older ones are marginalized).
DEFAULT_WINDOW = 100
#: The graph holds up to this many movements more than its window before the oldest leave (one
#: rebuild of the graph per this many movements).
WINDOW_STRIDE = 50
#: The smallest window: the map is rebuilt into its fast mode at CAREFUL_MOVEMENTS movements.
MIN_WINDOW = CAREFUL_MOVEMENTS


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


def due(state: MapState, window: int | None) -> bool:
    """Whether the map holds enough movements beyond ``window`` (None: no window) for the
    oldest to leave the graph."""
    return window is not None and len(state.placed) >= window + WINDOW_STRIDE


def marginalize_oldest(state: MapState, graph: MapGraph, window: int) -> None:
    """The placed movements older than the newest ``window`` leave the graph: their factors
    folded into the state's prior, their keyframes' poses and covariances and their bearings'
    residuals kept as numbers in ``state``; iSAM2 is rebuilt over the rest (no new solve: the
    values are the map's estimate)."""
    placed = sorted(state.placed)
    old = placed[: len(placed) - window]
    if not old:
        return
    old_set = set(old)
    values = graph.values
    old_keys = [g.pose_key(k, end) for k in old for end in (0, 1)]
    old_key_set = set(old_keys)
    # the factors that touch an old keyframe (and the prior) are folded; the rest are kept
    bearing_at = {i: b for b, i in graph.factor_of.items()}
    factors = graph.isam.getFactorsUnsafe()
    touching, rest = [], gtsam.NonlinearFactorGraph()
    rest_bearings: dict[int, g.Bearing] = {}
    n_rest = 0  # factors of ``rest`` other than bearings
    for i in range(factors.size()):
        f = factors.at(i)
        if f is None:  # taken out (a rejected bearing)
            continue
        b = bearing_at.get(i)
        if b is not None:  # most factors: a bearing, whose movement says where it goes
            if b.movement in old_set:
                touching.append(f)
            else:
                rest_bearings[len(rest_bearings) + n_rest] = b
                rest.add(f)
        elif isinstance(f, gtsam.LinearContainerFactor) or not old_key_set.isdisjoint(f.keys()):
            touching.append(f)
        else:
            rest.add(f)
            n_rest += 1
    isam = graph.isam

    def joint(keys: list[int]) -> NDArray[np.float64]:
        return np.asarray(isam.jointMarginalCovariance(keys).fullMatrix(), np.float64)

    done = marginalize(touching, values, old_keys, joint)
    rows = np.isin(graph.table.slot // 2, old)
    residuals = graph.residuals()
    frozen = dict(state.frozen)
    for k in old:
        p1, p2 = (values.atPose2(g.pose_key(k, end)) for end in (0, 1))
        frozen[k] = FrozenMovement(
            state.placed.pop(k),
            ((p1.x(), p1.y(), p1.theta()), (p2.x(), p2.y(), p2.theta())),
            (done.covariances.get(g.pose_key(k, 0)), done.covariances.get(g.pose_key(k, 1))),
        )
    state.frozen = frozen
    state.prior = done.prior
    state.frozen_bearings = state.frozen_bearings.plus(
        graph.table.landmark[rows].copy(), residuals[rows].copy(), graph.table.rejected[rows].copy()
    )
    gone = {link for link in state.links if old_set.intersection(link)}
    state.links -= gone
    state.frozen_links += len(gone)
    state.rejected = {b for b in state.rejected if b.movement not in old_set}
    state.pending = {
        name: kept
        for name, bearings in state.pending.items()
        if (kept := [b for b in bearings if b.movement not in old_set])
    }
    if done.prior is not None:
        rest.add(done.prior)
    graph.table = graph.table.subset(~rows)
    live_keys = [k for k in list(values.keys()) if k not in old_key_set]
    graph.restart(state, rest, rest_bearings, values.extract(live_keys))
