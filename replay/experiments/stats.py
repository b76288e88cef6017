"""Aggregates of the error rows: curves with 80% bands, paired differences, calibration.

The value of one run is the mean (over the chosen landmarks) of its error in centimetres; a band
is the mean of those values over runs with the 10th-90th percentile interval (the paper's 80%
intervals over the 40 runs).
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.special import stdtr

from replay.experiments.results import ErrorRow

#: the credible level the paper uses for its intervals
LEVEL = 0.8


@dataclass(frozen=True)
class Band:
    """Mean over runs with the central ``LEVEL`` interval (cm); ``n`` runs contributed."""

    mean: float
    lo: float
    hi: float
    n: int


@dataclass(frozen=True)
class PairedDifference:
    """Paired difference ``a - b`` over runs (cm): mean, two-sided t-test p value, run count."""

    mean: float
    std: float
    p_value: float
    n: int


def select(
    rows: Iterable[ErrorRow],
    *,
    method: str,
    group: str | None = None,
    n_l: int | None = None,
    movement: int | None = None,
    landmarks: Sequence[str] | None = None,
) -> list[ErrorRow]:
    """Rows matching every given field (None = any)."""
    return [
        r
        for r in rows
        if r.method == method
        and (group is None or r.group == group)
        and (n_l is None or r.n_l == n_l)
        and (movement is None or r.movement == movement)
        and (landmarks is None or r.landmark in landmarks)
    ]


def per_run(rows: Iterable[ErrorRow]) -> dict[int, float]:
    """Run -> mean error (cm) over the given rows of that run; runs with no estimate left out."""
    acc: dict[int, list[float]] = defaultdict(list)
    for r in rows:
        if math.isfinite(r.error_cm):
            acc[r.run].append(r.error_cm)
    return {run: float(np.mean(v)) for run, v in sorted(acc.items())}


def band(values: Sequence[float], level: float = LEVEL) -> Band:
    """Mean and central ``level`` percentile interval of ``values`` (NaN when empty)."""
    if len(values) == 0:
        return Band(math.nan, math.nan, math.nan, 0)
    v = np.asarray(values, dtype=np.float64)
    tail = 50.0 * (1.0 - level)
    lo, hi = np.percentile(v, [tail, 100.0 - tail])
    return Band(float(v.mean()), float(lo), float(hi), len(v))


def movement_curve(
    rows: Sequence[ErrorRow],
    *,
    method: str,
    n_l: int | None,
    landmarks: Sequence[str] | None = None,
    group: str | None = None,
) -> dict[int, Band]:
    """Movement count -> band of the per-run error over ``landmarks``."""
    chosen = select(rows, method=method, group=group, n_l=n_l, landmarks=landmarks)
    movements = sorted({r.movement for r in chosen})
    return {
        m: band(list(per_run(r for r in chosen if r.movement == m).values())) for m in movements
    }


def n_l_curve(
    rows: Sequence[ErrorRow],
    *,
    method: str,
    movement: int,
    landmarks: Sequence[str] | None = None,
    group: str | None = None,
) -> dict[int, Band]:
    """n_l -> band of the per-run error after ``movement`` movements."""
    chosen = select(rows, method=method, group=group, movement=movement, landmarks=landmarks)
    return {
        n: band(list(per_run(r for r in chosen if r.n_l == n).values()))
        for n in sorted({r.n_l for r in chosen})
    }


def paired_difference(a: dict[int, float], b: dict[int, float]) -> PairedDifference:
    """Paired t-test of ``a - b`` over the runs both have (two-sided p value)."""
    runs = sorted(set(a) & set(b))
    d = np.array([a[r] - b[r] for r in runs], dtype=np.float64)
    if len(d) < 2:
        return PairedDifference(float(d.mean()) if len(d) else math.nan, math.nan, math.nan, len(d))
    std = float(d.std(ddof=1))
    if std == 0.0:
        p = 1.0 if d.mean() == 0.0 else 0.0
    else:
        t = float(d.mean()) / (std / math.sqrt(len(d)))
        p = float(2.0 * stdtr(len(d) - 1, -abs(t)))
    return PairedDifference(float(d.mean()), std, p, len(d))


def paired_ratio(a: dict[int, float], b: dict[int, float]) -> float:
    """Mean of ``a`` over mean of ``b``, both over the runs both have (NaN: none, or ``b`` 0).

    A method with no estimate in some runs (its first movements skipped) is compared with the
    yardstick on its own runs only, not with the yardstick's mean over every run.
    """
    runs = sorted(set(a) & set(b))
    if not runs:
        return math.nan
    den = float(np.mean([b[r] for r in runs]))
    return float(np.mean([a[r] for r in runs])) / den if den > 0.0 else math.nan


def calibration(rows: Iterable[ErrorRow]) -> tuple[float, int]:
    """Fraction of estimates whose 80% region holds the truth, and how many were checked."""
    flags = [r.inside_80 for r in rows if r.inside_80 is not None]
    if not flags:
        return math.nan, 0
    return float(np.mean(flags)), len(flags)
