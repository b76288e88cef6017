"""``bslam experiment calibration``: the joint map's 80% regions per arena family, on chosen seeds.

Every family of :mod:`replay.experiments.families` (or the ones asked for) is run ``runs`` times,
run ``i`` from seed ``seed + i`` (each family draws its own scenario from that seed), through
:func:`replay.experiments.calibration.score_run`: a simulated log, its bearings, the joint
estimator and batch least squares. Per family (:func:`family_coverage`): the share of landmarks
whose truth lies in their 80% region, with a bootstrap interval over runs (the regions of one run
share its keyframes, so a binomial interval over regions would be too narrow), the median squared
Mahalanobis distance, the regions whose truth lies beyond 99.99%, and the mean error against batch
least squares', with a bootstrap interval over runs and the median of the runs' own ratios (a
run or two where one of the two goes far off can decide a ratio of means). Written to
``out_dir``: ``scores.jsonl`` (one line per landmark scored), ``calibration.json`` (the
per-family figures, the failed runs, the command) and ``calibration.md`` (the table).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from replay.experiments.calibration import LandmarkScore, score_run
from replay.experiments.results import json_float
from replay.parallel import run_tasks

#: Resamples of the bootstrap over runs.
BOOTSTRAP_RESAMPLES = 2000
#: Level of the bootstrap interval of the coverage.
INTERVAL_LEVEL = 0.90
#: Squared Mahalanobis radius of the 99.99% region (chi-square with 2 degrees of freedom).
CHI2_2_9999 = -2.0 * math.log(1e-4)


@dataclass(frozen=True)
class FamilyCoverage:
    """Calibration figures of one family.

    Attributes
    ----------
    family : str
    runs, failed : int
        Runs scored, and runs that failed (left out).
    regions : int
        Landmarks scored (the reference pair is not: it is the frame).
    inside : float
        Share of the regions that hold the truth (NaN: none scored).
    interval : (float, float)
        :data:`INTERVAL_LEVEL` bootstrap interval of ``inside`` over runs.
    median_d2 : float
        Median squared Mahalanobis distance of the truth (chi-square(2): 1.39).
    beyond_9999 : int
        Regions whose truth lies beyond their 99.99% region.
    error_cm, batch_ls_cm : float
        Mean error of the joint map and of batch least squares over the landmarks both placed.
    ratio_to_ls : float
        ``error_cm / batch_ls_cm`` (NaN when least squares placed none).
    ratio_interval : (float, float)
        :data:`INTERVAL_LEVEL` bootstrap interval of ``ratio_to_ls`` over runs.
    median_run_ratio : float
        Median over runs of each run's own ``error_cm / batch_ls_cm``.
    """

    family: str
    runs: int
    failed: int
    regions: int
    inside: float
    interval: tuple[float, float]
    median_d2: float
    beyond_9999: int
    error_cm: float
    batch_ls_cm: float
    ratio_to_ls: float
    ratio_interval: tuple[float, float]
    median_run_ratio: float


def family_coverage(
    family: str,
    runs: Sequence[Sequence[LandmarkScore]],
    rng: np.random.Generator,
    failed: int = 0,
) -> FamilyCoverage:
    """The figures of one family from its runs' scores (one sequence per run); ``rng`` draws
    the bootstrap resamples."""
    d2 = np.array([s.d2 for run in runs for s in run], np.float64)
    inside_per_run = np.array([sum(s.inside for s in run) for run in runs], np.float64)
    regions_per_run = np.array([len(run) for run in runs], np.float64)
    nan = math.nan
    if d2.size == 0:
        return FamilyCoverage(
            family, len(runs), failed, 0, nan, (nan, nan), nan, 0, nan, nan, nan, (nan, nan), nan
        )
    picks = rng.integers(0, len(runs), size=(BOOTSTRAP_RESAMPLES, len(runs)))
    tail = 100.0 * (1.0 - INTERVAL_LEVEL) / 2.0

    def interval(num: NDArray[np.float64], den: NDArray[np.float64]) -> tuple[float, float]:
        """Bootstrap interval of sum(num) / sum(den), the runs resampled by ``picks``."""
        n, d = num[picks].sum(axis=1), den[picks].sum(axis=1)
        if not (d > 0.0).any():
            return nan, nan
        lo, hi = np.percentile(n[d > 0.0] / d[d > 0.0], [tail, 100.0 - tail])
        return float(lo), float(hi)

    # per run: the joint map's and least squares' summed error over the landmarks both placed
    error_run, ls_run, n_run = (np.zeros(len(runs)) for _ in range(3))
    for i, run in enumerate(runs):
        for s in run:
            if math.isfinite(s.error_cm) and math.isfinite(s.batch_ls_cm):
                error_run[i] += s.error_cm
                ls_run[i] += s.batch_ls_cm
                n_run[i] += 1
    placed = n_run > 0
    error_cm = float(error_run.sum() / n_run.sum()) if placed.any() else nan
    ls_cm = float(ls_run.sum() / n_run.sum()) if placed.any() else nan
    own = placed & (ls_run > 0.0)
    return FamilyCoverage(
        family,
        len(runs),
        failed,
        int(d2.size),
        float(inside_per_run.sum() / regions_per_run.sum()),
        interval(inside_per_run, regions_per_run),
        float(np.median(d2)),
        int((d2 > CHI2_2_9999).sum()),
        error_cm,
        ls_cm,
        error_cm / ls_cm if ls_cm > 0.0 else nan,
        interval(error_run, ls_run),
        float(np.median(error_run[own] / ls_run[own])) if own.any() else nan,
    )


def table_markdown(rows: Sequence[FamilyCoverage]) -> str:
    """The per-family figures as a markdown table."""
    lines = [
        "| family | runs | regions | inside the 80% region | 90% interval | median d^2 "
        "(chi2(2): 1.39) | beyond 99.99% | joint / batch LS (mean error) | 90% interval | "
        "median run's ratio |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]

    def num(x: float) -> str:
        return f"{x:.2f}" if math.isfinite(x) else "-"

    for r in rows:
        failed = f" ({r.failed} failed)" if r.failed else ""
        if r.regions == 0:
            lines.append(f"| {r.family} | {r.runs}{failed} | 0 | - | - | - | - | - | - | - |")
            continue
        lo, hi = r.ratio_interval
        lines.append(
            f"| {r.family} | {r.runs}{failed} | {r.regions} | {100 * r.inside:.1f}% | "
            f"{100 * r.interval[0]:.1f}-{100 * r.interval[1]:.1f}% | {r.median_d2:.2f} | "
            f"{r.beyond_9999} | {num(r.ratio_to_ls)} | "
            f"{num(lo) + '-' + num(hi) if math.isfinite(lo) else '-'} | "
            f"{num(r.median_run_ratio)} |"
        )
    return "\n".join(lines) + "\n"


@dataclass(frozen=True)
class CalibrationResults:
    """What :func:`calibration_experiment` measured: per-family figures, and the failed runs
    as ``(family, seed, reason)``."""

    families: list[FamilyCoverage]
    failures: list[tuple[str, int, str]]
    elapsed_s: float


def _plain(value: Any) -> Any:
    """``value`` with every float that is not finite as None (for JSON)."""
    if isinstance(value, float):
        return json_float(value)
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def _score(task: tuple[str, int]) -> list[LandmarkScore]:
    """One run (a worker's task): ``(family, seed)``."""
    return score_run(*task)


def calibration_experiment(
    out_dir: Path,
    families: Sequence[str],
    runs: int,
    seed: int,
    *,
    workers: int = 1,
    scheduler: str | None = None,
    progress: bool = True,
    command: str = "",
) -> CalibrationResults:
    """Run and score ``runs`` runs of each of ``families`` (run ``i`` from seed ``seed + i``);
    write ``scores.jsonl``, ``calibration.json`` and ``calibration.md`` into ``out_dir``."""
    start = time.perf_counter()
    tasks = [(family, seed + i) for family in families for i in range(runs)]
    outcomes = run_tasks(
        _score, tasks, workers=workers, scheduler=scheduler, progress=progress, desc="runs"
    )
    out_dir.mkdir(parents=True, exist_ok=True)
    per_family: dict[str, list[list[LandmarkScore]]] = {f: [] for f in families}
    failures: list[tuple[str, int, str]] = []
    with (out_dir / "scores.jsonl").open("w") as fh:
        for (family, run_seed), outcome in zip(tasks, outcomes, strict=True):
            if outcome.value is None:
                failures.append((family, run_seed, outcome.error or "failed"))
                continue
            per_family[family].append(outcome.value)
            for s in outcome.value:
                fh.write(
                    json.dumps(_plain({**asdict(s), "inside": s.inside}), allow_nan=False) + "\n"
                )
    rng = np.random.default_rng(seed)
    rows = [
        family_coverage(f, per_family[f], rng, sum(1 for x in failures if x[0] == f))
        for f in families
    ]
    results = CalibrationResults(rows, failures, round(time.perf_counter() - start, 2))
    doc = {
        "command": command,
        "runs_per_family": runs,
        "seeds": [seed, seed + runs - 1],
        "families": [asdict(r) for r in rows],
        "failed": [{"family": f, "seed": s, "reason": why} for f, s, why in failures],
        "elapsed_s": results.elapsed_s,
    }
    (out_dir / "calibration.json").write_text(
        json.dumps(_plain(doc), indent=1, allow_nan=False) + "\n"
    )
    header = f"Calibration of the joint map, seeds {seed}-{seed + runs - 1} per family"
    (out_dir / "calibration.md").write_text(f"# {header}\n\n`{command}`\n\n{table_markdown(rows)}")
    return results
