"""Batch least squares: 2-D bundle adjustment over all bearings (docs/method.md, part 8).

Unknowns: every non-reference landmark's position in FL, and per movement its start point
``O1`` (FL), heading and log-length (so ``O2 = O1 + e^l (cos h, sin h)``). Gauge: the reference
pair is fixed at L1 = (0, 0), L2 = (1, 0). Residuals: wrapped bearing errors
``wrap(measured - (atan2(L - O) - h))`` at O1 and O2. Solved with
``scipy.optimize.least_squares`` (trust-region reflective, the Jacobian by hand).

Initial guess, per movement: triangulate every landmark in FR from its two bearings, send the
reference pair to FL with the same similarity as :mod:`pipeline.frame_change`; landmarks start at
the median of their FL triangulations. Movements whose reference pair cannot be triangulated
(rays nearly parallel or not meeting in front) are left out.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad
from data_schemas.errors import EstimationError
from pipeline.frame_change import to_fl
from pipeline.geometry import triangulate_fr
from pipeline.slam import MovementObservation


def batch_least_squares(
    observations: Sequence[MovementObservation],
    landmarks: Sequence[str],
    reference: tuple[str, str],
) -> dict[str, NDArray[np.float64]]:
    """Least-squares positions (2,) FL of the non-reference landmarks seen in usable movements."""
    l1, l2 = reference
    moves: list[tuple[MovementObservation, NDArray[np.float64], NDArray[np.float64]]] = []
    seeds: dict[str, list[NDArray[np.float64]]] = {}
    for obs in observations:
        b1, b2 = obs.bearings_o1_rad, obs.bearings_o2_rad
        if not all(r in b1 and r in b2 for r in reference):
            continue
        s1 = triangulate_fr(b1[l1], b2[l1])
        s2 = triangulate_fr(b1[l2], b2[l2])
        if s1 is None or s2 is None:
            continue
        o_fl = to_fl(np.array([[0.0, 0.0], [1.0, 0.0]]), s1, s2)
        moves.append((obs, o_fl[0], o_fl[1]))
        for name in landmarks:
            if name in reference or name not in b1 or name not in b2:
                continue
            p = triangulate_fr(b1[name], b2[name])
            if p is not None:
                seeds.setdefault(name, []).append(to_fl(p, s1, s2))
    free = [n for n in landmarks if n not in reference and n in seeds]
    if not moves:
        raise EstimationError("no movement sees the reference pair with enough parallax")
    col = {n: i for i, n in enumerate(free)}
    fixed = {l1: np.array([0.0, 0.0]), l2: np.array([1.0, 0.0])}
    # observation table: movement k, landmark slot (-1/-2 fixed refs), end (0 = O1, 1 = O2)
    mk, slot, end, meas = [], [], [], []
    for k, (obs, _, _) in enumerate(moves):
        for e, bmap in enumerate((obs.bearings_o1_rad, obs.bearings_o2_rad)):
            for name, b in bmap.items():
                if name in col or name in fixed:
                    mk.append(k)
                    slot.append(col.get(name, -1 if name == l1 else -2))
                    end.append(e)
                    meas.append(b)
    mk_a = np.array(mk)
    slot_a = np.array(slot)
    end_a = np.array(end, dtype=np.float64)
    meas_a = np.array(meas)
    nf = len(free)

    def rays(x: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
        """Per bearing: the heading h, L e (the observer's offset from O1 along h) and the ray
        from the observer to the landmark (dx, dy)."""
        lm = np.vstack((x[: 2 * nf].reshape(nf, 2), fixed[l2], fixed[l1]))  # -2 -> l2, -1 -> l1
        mv = x[2 * nf :].reshape(-1, 4)
        h = mv[mk_a, 2]
        le = np.exp(mv[mk_a, 3]) * end_a
        p = lm[slot_a]
        return (
            h,
            le,
            p[:, 0] - (mv[mk_a, 0] + le * np.cos(h)),
            p[:, 1] - (mv[mk_a, 1] + le * np.sin(h)),
        )

    def residuals(x: NDArray[np.float64]) -> NDArray[np.float64]:
        h, _, dx, dy = rays(x)
        out: NDArray[np.float64] = wrap_rad(meas_a - (np.arctan2(dy, dx) - h))
        return out

    rows = np.arange(len(meas_a))
    lm_col = np.where(slot_a >= 0, 2 * slot_a, -1)  # fixed references: no column
    mv_col = 2 * nf + 4 * mk_a
    own = lm_col >= 0

    def jacobian(x: NDArray[np.float64]) -> NDArray[np.float64]:
        """d residuals / d x, by hand: with the ray d = P - O (q = |d|^2), the residual moves by
        (dy, -dx) / q with P, by (-dy, dx) / q with O1, by 1 + L e (dx cos h + dy sin h) / q
        with the heading and by -L e (dy cos h - dx sin h) / q with the log length (O = O1 + L
        e (cos h, sin h), e = 0 at O1 and 1 at O2)."""
        h, le, dx, dy = rays(x)
        c, s = np.cos(h), np.sin(h)
        q = dx * dx + dy * dy
        jac = np.zeros((len(meas_a), x.size))
        jac[rows[own], lm_col[own]] = (dy / q)[own]
        jac[rows[own], lm_col[own] + 1] = (-dx / q)[own]
        jac[rows, mv_col] = -dy / q
        jac[rows, mv_col + 1] = dx / q
        jac[rows, mv_col + 2] = 1.0 + le * (dx * c + dy * s) / q
        jac[rows, mv_col + 3] = -le * (dy * c - dx * s) / q
        return jac

    x0 = [np.median(np.array(seeds[n]), axis=0) for n in free]
    for _, o1, o2 in moves:
        d = o2 - o1
        x0.append(np.array([o1[0], o1[1], math.atan2(d[1], d[0]), math.log(math.hypot(*d))]))
    from scipy.optimize import least_squares  # ~0.5 s to import: only when a fit is made

    sol = least_squares(
        residuals, np.concatenate(x0) if x0 else np.zeros(0), jac=jacobian, method="trf"
    )
    return {n: sol.x[2 * i : 2 * i + 2].copy() for i, n in enumerate(free)}
