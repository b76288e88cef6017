"""``bslam experiment calibration``: the joint map's 80% regions per arena family, on chosen seeds.

Every family of :mod:`replay.experiments.families` (or the ones asked for) is run ``runs`` times,
run ``i`` from seed ``seed + i`` (each family draws its own scenario from that seed), through
:func:`replay.experiments.calibration.score_run`: a simulated log, its bearings, the joint
estimator and batch least squares. Per family (:func:`family_coverage`): the share of landmarks
whose truth lies in their 80% region, with a bootstrap interval over runs (the regions of one run
share its keyframes, so a binomial interval over regions would be too narrow), the median squared
Mahalanobis distance, the regions whose truth lies beyond 99.99%, and the mean error against batch
least squares'. Written to ``out_dir``: ``scores.jsonl`` (one line per landmark scored),
``calibration.json`` (the per-family figures, the failed runs, the command) and
``calibration.md`` (the table).
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
        return FamilyCoverage(family, len(runs), failed, 0, nan, (nan, nan), nan, 0, nan, nan, nan)
    picks = rng.integers(0, len(runs), size=(BOOTSTRAP_RESAMPLES, len(runs)))
    regions = regions_per_run[picks].sum(axis=1)
    shares = inside_per_run[picks].sum(axis=1)[regions > 0] / regions[regions > 0]
    tail = 100.0 * (1.0 - INTERVAL_LEVEL) / 2.0
    lo, hi = np.percentile(shares, [tail, 100.0 - tail])
    error = np.array([s.error_cm for run in runs for s in run], np.float64)
    ls = np.array([s.batch_ls_cm for run in runs for s in run], np.float64)
    both = np.isfinite(error) & np.isfinite(ls)
    error_cm = float(error[both].mean()) if both.any() else nan
    ls_cm = float(ls[both].mean()) if both.any() else nan
    return FamilyCoverage(
        family,
        len(runs),
        failed,
        int(d2.size),
        float(inside_per_run.sum() / regions_per_run.sum()),
        (float(lo), float(hi)),
        float(np.median(d2)),
        int((d2 > CHI2_2_9999).sum()),
        error_cm,
        ls_cm,
        error_cm / ls_cm if ls_cm > 0.0 else nan,
    )


def table_markdown(rows: Sequence[FamilyCoverage]) -> str:
    """The per-family figures as a markdown table."""
    lines = [
        "| family | runs | regions | inside the 80% region | 90% interval | median d^2 "
        "(chi2(2): 1.39) | beyond 99.99% | joint / batch LS (mean error) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        failed = f" ({r.failed} failed)" if r.failed else ""
        if r.regions == 0:
            lines.append(f"| {r.family} | {r.runs}{failed} | 0 | - | - | - | - | - |")
            continue
        ratio = f"{r.ratio_to_ls:.2f}" if math.isfinite(r.ratio_to_ls) else "-"
        lines.append(
            f"| {r.family} | {r.runs}{failed} | {r.regions} | {100 * r.inside:.1f}% | "
            f"{100 * r.interval[0]:.1f}-{100 * r.interval[1]:.1f}% | {r.median_d2:.2f} | "
            f"{r.beyond_9999} | {ratio} |"
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
