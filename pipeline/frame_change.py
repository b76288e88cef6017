"""Change of frame FR -> FL (docs/method.md, part 4).

Each pair ``(s1, s2)`` of reference particles defines the similarity that sends ``s1`` to
(0, 0) and ``s2`` to (1, 0): with ``d = s2 - s1`` and ``u = z - s1``,
``z_fl = (u . d, d x u) / |d|^2``. Written in real arithmetic so that ``s1 -> (0, 0)`` and
``s2 -> (1, 0)`` hold exactly in floating point.

Two ways to build the FL sets (all particles are equally weighted, so both target the same
distribution):

* ``"exact"`` (the paper): enumerate all ``n_r^2`` pairs for O1 and O2 and all ``n_r^3`` triples
  for each other landmark, in chunks of at most ``chunk_elems`` triples (bounded memory), and
  keep ``n_l`` of the triples drawn uniformly without replacement;
* ``"sampled"``: draw ``n_l`` index triples ``(i, j, k)`` at random: O(n_l). O1 and O2 get the
  same ``n_l`` pairs ``(i, j)``, shared by all landmarks of the movement (joint samples).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

FrameChange = Literal["sampled", "exact"]

#: Default cap on triples held in memory at once by the exact enumeration (~16 MB per array).
CHUNK_ELEMS = 1 << 20


@dataclass
class FlSets:
    """Output of a change of frame: particles in FL.

    Attributes
    ----------
    o1_fl, o2_fl : ndarray (m, 2)
        Observation points (m = n_r^2 exact, n_l sampled).
    landmarks_fl : dict of name -> ndarray (n_l, 2)
        Every non-reference landmark.
    """

    o1_fl: NDArray[np.float64]
    o2_fl: NDArray[np.float64]
    landmarks_fl: dict[str, NDArray[np.float64]]


def to_fl(
    z: NDArray[np.float64], s1: NDArray[np.float64], s2: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Apply the similarity ``s1 -> (0,0), s2 -> (1,0)`` elementwise (broadcasting, (..., 2))."""
    dx = s2[..., 0] - s1[..., 0]
    dy = s2[..., 1] - s1[..., 1]
    ux = z[..., 0] - s1[..., 0]
    uy = z[..., 1] - s1[..., 1]
    n2 = dx * dx + dy * dy  # divide (not multiply by 1/n2) so s2 -> (1, 0) exactly
    return np.stack(((ux * dx + uy * dy) / n2, (uy * dx - ux * dy) / n2), axis=-1)


def from_fl(
    z_fl: NDArray[np.float64], s1: NDArray[np.float64], s2: NDArray[np.float64]
) -> NDArray[np.float64]:
    """The inverse of :func:`to_fl`: points (..., 2) of the frame ``s1 -> (0,0), s2 -> (1,0)``
    back where ``s1`` and ``s2`` are (broadcasting)."""
    dx = s2[..., 0] - s1[..., 0]
    dy = s2[..., 1] - s1[..., 1]
    u, v = z_fl[..., 0], z_fl[..., 1]
    return np.stack((s1[..., 0] + u * dx - v * dy, s1[..., 1] + u * dy + v * dx), axis=-1)


def _pairs_fl(
    s1: NDArray[np.float64], s2: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """O1 = (0,0) and O2 = (1,0) (FR) sent to FL through every given pair."""
    dx = s2[:, 0] - s1[:, 0]
    dy = s2[:, 1] - s1[:, 1]
    inv = 1.0 / (dx * dx + dy * dy)
    # O1: u = -s1; O2: u = (1,0) - s1
    ux, uy = -s1[:, 0], -s1[:, 1]
    o1 = np.column_stack(((ux * dx + uy * dy) * inv, (uy * dx - ux * dy) * inv))
    ux2 = ux + 1.0
    o2 = np.column_stack(((ux2 * dx + uy * dy) * inv, (uy * dx - ux2 * dy) * inv))
    return o1, o2


def change_frame_sampled(
    s1: NDArray[np.float64],
    s2: NDArray[np.float64],
    others: Mapping[str, NDArray[np.float64]],
    n_l: int,
    rng: np.random.Generator,
) -> FlSets:
    """O(n_l) change of frame: one random index per set for each output particle."""
    n1, n2 = s1.shape[0], s2.shape[0]
    i = rng.integers(0, n1, n_l)
    j = rng.integers(0, n2, n_l)
    a, b = s1[i], s2[j]
    o1, o2 = _pairs_fl(a, b)
    out = {name: to_fl(s[rng.integers(0, s.shape[0], n_l)], a, b) for name, s in others.items()}
    return FlSets(o1, o2, out)


def change_frame_exact(
    s1: NDArray[np.float64],
    s2: NDArray[np.float64],
    others: Mapping[str, NDArray[np.float64]],
    n_l: int,
    rng: np.random.Generator,
    *,
    chunk_elems: int = CHUNK_ELEMS,
) -> FlSets:
    """Enumerate all pairs (O1, O2) and all triples (landmarks), chunked; keep ``n_l`` per set.

    Peak memory is O(max(chunk_elems, n_r^2)) whatever ``n_r``.
    """
    n1, n2 = s1.shape[0], s2.shape[0]
    ii, jj = np.divmod(np.arange(n1 * n2), n2)
    o1, o2 = _pairs_fl(s1[ii], s2[jj])
    out: dict[str, NDArray[np.float64]] = {}
    for name, s in others.items():
        nk = s.shape[0]
        block = n2 * nk  # triples per s1 index
        rows = max(1, chunk_elems // block)
        total = n1 * block
        # a uniform subsample of the enumeration (all triples are equally weighted); systematic
        # pointers would alias with the (i, j, k) ordering
        ptr = np.sort(rng.choice(total, n_l, replace=n_l > total))
        res = np.empty((n_l, 2))
        for start in range(0, n1, rows):
            stop = min(n1, start + rows)
            # every triple (i, j, k) of this chunk, in FL: shape (rows, n2, nk, 2)
            full = to_fl(
                s[None, None, :, :], s1[start:stop, None, None, :], s2[None, :, None, :]
            ).reshape(-1, 2)
            lo, hi = np.searchsorted(ptr, (start * block, stop * block))
            res[lo:hi] = full[ptr[lo:hi] - start * block]
        out[name] = res
    return FlSets(o1, o2, out)


def change_frame(
    s1: NDArray[np.float64],
    s2: NDArray[np.float64],
    others: Mapping[str, NDArray[np.float64]],
    n_l: int,
    rng: np.random.Generator,
    method: FrameChange = "sampled",
) -> FlSets:
    """Change of frame FR -> FL by ``method`` (``"sampled"`` or ``"exact"``)."""
    if method == "exact":
        return change_frame_exact(s1, s2, others, n_l, rng)
    return change_frame_sampled(s1, s2, others, n_l, rng)
