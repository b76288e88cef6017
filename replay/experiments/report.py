"""The headline numbers of an experiment and the generated ``report.md``.

:func:`method_table` gives one row per method (error after the paper's 3 movements and after the
last one, ratio to batch least squares, calibration, paired difference to the impartial PDF);
:func:`write_report` puts them, the figures and the paper's numbers side by side.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from replay.experiments.results import CRB, METHOD_LABELS, PAPER_ERROR_CM, Results
from replay.experiments.stats import (
    Band,
    PairedDifference,
    calibration,
    movement_curve,
    n_l_curve,
    paired_difference,
    paired_ratio,
    per_run,
    select,
)


@dataclass(frozen=True)
class MethodRow:
    """One method's line of the comparison table (errors in cm over the scored landmarks).

    The ratios to batch least squares are taken over the runs where both have an estimate.
    """

    method: str
    early: Band
    final: Band
    ratio_to_ls_early: float
    ratio_to_ls_final: float
    coverage_80: float
    vs_impartial: PairedDifference | None


def _n_l(cfg: dict[str, Any], method: str, group: str | None = None) -> int:
    """Particles in FL of ``method``'s rows: 0 for yardsticks, the group's value in an n_l sweep."""
    if method not in cfg["protocol"]["priors"]:
        return 0
    if group is not None and cfg.get("param") == "n_l":
        return int(group.split("=", 1)[1])
    return int(cfg["protocol"]["n_l"])


def _nan_band() -> Band:
    return Band(math.nan, math.nan, math.nan, 0)


def method_table(results: Results, *, group: str | None = None) -> list[MethodRow]:
    """Comparison rows for every method of the experiment (one group of a sweep if given)."""
    cfg = results.config
    scored = cfg["scored_landmarks"]
    early_m = int(cfg["protocol"]["n_l_movements"])
    final_m = int(cfg["protocol"]["movements"])
    curves = {
        m: movement_curve(
            results.rows, method=m, n_l=_n_l(cfg, m, group), landmarks=scored, group=group
        )
        for m in cfg["methods"]
    }

    def run_values(method: str, movement: int) -> dict[int, float]:
        chosen = select(
            results.rows,
            method=method,
            n_l=_n_l(cfg, method, group),
            movement=movement,
            landmarks=scored,
            group=group,
        )
        return per_run(chosen)

    table = []
    for method, curve in curves.items():
        early = curve.get(early_m, _nan_band())
        final = curve.get(final_m, _nan_band())
        ratios = [
            paired_ratio(run_values(method, m), run_values("batch_ls", m))
            if "batch_ls" in curves
            else math.nan
            for m in (early_m, final_m)
        ]
        n_l = _n_l(cfg, method, group)
        coverage, _ = calibration(
            select(results.rows, method=method, n_l=n_l, landmarks=scored, group=group)
        )
        vs = None
        if method not in ("impartial", CRB) and "impartial" in curves:
            vs = paired_difference(run_values(method, early_m), run_values("impartial", early_m))
        table.append(
            MethodRow(
                method,
                early,
                final,
                ratios[0],
                ratios[1],
                coverage,
                vs,
            )
        )
    return table


def _fmt(x: float, digits: int = 2) -> str:
    return "–" if not math.isfinite(x) else f"{x:.{digits}f}"


def _band(b: Band) -> str:
    return "–" if b.n == 0 else f"{_fmt(b.mean)} [{_fmt(b.lo)}, {_fmt(b.hi)}]"


def table_markdown(results: Results, *, group: str | None = None) -> str:
    """The comparison table as Markdown."""
    cfg = results.config
    early_m, final_m = cfg["protocol"]["n_l_movements"], cfg["protocol"]["movements"]
    lines = [
        f"| method | error after {early_m} mov. (cm) | error after {final_m} mov. (cm) "
        f"| / batch LS ({early_m}, {final_m}) | 80% region holds truth "
        f"| minus impartial after {early_m} (cm, p) |",
        "|---|---|---|---|---|---|",
    ]
    for row in method_table(results, group=group):
        vs = "–"
        if row.vs_impartial is not None and math.isfinite(row.vs_impartial.mean):
            vs = f"{row.vs_impartial.mean:+.2f} (p = {_fmt(row.vs_impartial.p_value, 3)})"
        cover = "–"
        if row.method not in (CRB, "batch_ls") and math.isfinite(row.coverage_80):
            cover = f"{100 * row.coverage_80:.0f}%"
        lines.append(
            f"| {METHOD_LABELS[row.method]} | {_band(row.early)} | {_band(row.final)} "
            f"| {_fmt(row.ratio_to_ls_early)}, {_fmt(row.ratio_to_ls_final)} | {cover} | {vs} |"
        )
    return "\n".join(lines)


def sweep_table_markdown(results: Results) -> str:
    """One line per swept value: each method's mean error after the early and the last movement,
    and how often the impartial PDF's 80% region holds the truth."""
    cfg = results.config
    early_m, final_m = cfg["protocol"]["n_l_movements"], cfg["protocol"]["movements"]
    methods = cfg["methods"]
    lines = [
        f"Mean error (cm) over runs after {early_m} / {final_m} movements:",
        "",
        f"| {cfg['param']} | "
        + " | ".join(METHOD_LABELS[m] for m in methods)
        + " | impartial: 80% region holds truth |",
        "|---|" + "---|" * (len(methods) + 1),
    ]
    for value in cfg["values"]:
        rows = {r.method: r for r in method_table(results, group=f"{cfg['param']}={value}")}
        cells = [f"{_fmt(rows[m].early.mean)} / {_fmt(rows[m].final.mean)}" for m in methods]
        imp = rows.get("impartial")
        cover = (
            "–"
            if imp is None or not math.isfinite(imp.coverage_80)
            else (f"{100 * imp.coverage_80:.0f}%")
        )
        lines.append(f"| {value} | " + " | ".join(cells) + f" | {cover} |")
    return "\n".join(lines)


def n_l_flatness(results: Results) -> tuple[dict[int, Band], float]:
    """Fig. 8 bands and their relative spread (max - min) / mean of the means."""
    cfg = results.config
    bands = n_l_curve(
        results.rows,
        method="impartial",
        movement=cfg["protocol"]["n_l_movements"],
        landmarks=cfg["scored_landmarks"],
    )
    means = [b.mean for b in bands.values() if b.n]
    if not means:
        return bands, math.nan
    spread = (max(means) - min(means)) / (sum(means) / len(means))
    return bands, spread


def _geometry(cfg: dict[str, Any]) -> str:
    g = cfg["geometry"]
    marks = ", ".join(f"{n} ({x:.1f}, {y:.1f})" for n, (x, y) in g["landmarks_cm"].items())
    return (
        f"arena {g['arena_cm'][0]:.0f} x {g['arena_cm'][1]:.0f} cm; |L1 L2| = "
        f"{g['baseline_cm']:.1f} cm; landmarks (cm, world): {marks}; camera "
        f"{g['camera']}; bearing noise {g['bearing_noise_deg']}°, bound eps = "
        f"{g['vision_error_deg']}°; movement length {g['movement_length']}"
    )


def write_report(results: Results, out_dir: Path, figures: dict[str, str]) -> Path:
    """Write ``report.md`` in ``out_dir`` (``figures``: caption -> PNG name) and return it."""
    cfg = results.config
    proto = cfg["protocol"]
    early_m, final_m = proto["n_l_movements"], proto["movements"]
    imp = movement_curve(
        results.rows, method="impartial", n_l=proto["n_l"], landmarks=cfg["scored_landmarks"]
    )
    early = imp.get(early_m, _nan_band())
    final = imp.get(final_m, _nan_band())
    bands, spread = n_l_flatness(results)
    mixture = next((r for r in method_table(results) if r.method == "mixture"), None)
    ok = len(results.runs) - len(results.failed())
    elapsed_s = float(results.info.get("elapsed_s", math.nan))
    lines = [
        f"# {results.experiment} experiment",
        "",
        f"Command: `{results.info.get('command', '')}`",
        "",
        f"{ok} of {len(results.runs)} runs succeeded in {elapsed_s:.1f} s "
        f"({results.info.get('workers', '?')} workers). Geometry: {_geometry(cfg)}. "
        f"n_r = {proto['n_r']}, n_l = {proto['n_l']}, frame change: {proto['frame_change']}. "
        "Errors are distances in FL converted to cm with the true |L1 L2|; bands are 10th-90th "
        "percentiles over runs.",
        "",
        "## Paper versus this run",
        "",
        "| claim | paper | here |",
        "|---|---|---|",
        f"| mean error on {', '.join(cfg['scored_landmarks'])} after {early_m} movements "
        f"| about {PAPER_ERROR_CM:.0f} cm | {_band(early)} cm |",
        f"| ... after {final_m} movements | not much lower | {_band(final)} cm |",
        f"| error after {early_m} movements vs n_l | flat from 50 to 1000 | "
        + ", ".join(f"{n}: {_fmt(b.mean)}" for n, b in bands.items())
        + f" cm (spread {100 * spread:.0f}% of the mean) |",
    ]
    if mixture is not None and mixture.vs_impartial is not None:
        lines.append(
            "| impartial vs mixture of Gaussians | no significant difference | mixture minus "
            f"impartial {mixture.vs_impartial.mean:+.2f} cm, paired t-test p = "
            f"{_fmt(mixture.vs_impartial.p_value, 3)} |"
        )
    lines += ["", "## Methods on the same bearings", "", table_markdown(results), ""]
    for caption, name in figures.items():
        lines += [f"### {caption}", "", f"![{caption}]({name})", ""]
    return _write_report(lines, results, out_dir)


def write_sweep_report(results: Results, out_dir: Path, figure: str) -> Path:
    """Write ``report.md`` for a sweep: the figure and one comparison table per value."""
    cfg = results.config
    ok = len(results.runs) - len(results.failed())
    elapsed_s = float(results.info.get("elapsed_s", math.nan))
    lines = [
        f"# {results.experiment}",
        "",
        f"Command: `{results.info.get('command', '')}`",
        "",
        f"{ok} of {len(results.runs)} runs succeeded in {elapsed_s:.1f} s. Base geometry: "
        f"{_geometry(cfg)}. Errors in cm (FL times the true |L1 L2|); bands are 10th-90th "
        "percentiles over runs.",
        "",
        sweep_table_markdown(results),
        "",
        f"![sweep]({figure})",
        "",
    ]
    for value in cfg["values"]:
        group = f"{cfg['param']}={value}"
        lines += [f"## {group}", "", table_markdown(results, group=group), ""]
    return _write_report(lines, results, out_dir)


def _write_report(lines: list[str], results: Results, out_dir: Path) -> Path:
    """Append the failed runs (if any) to ``lines`` and write them as ``out_dir/report.md``."""
    failed = results.failed()
    if failed:
        lines += ["## Failed runs", ""]
        lines += [f"- {r.group} run {r.run} (seed {r.seed}): {r.status}" for r in failed]
        lines.append("")
    path = out_dir / "report.md"
    path.write_text("\n".join(lines), encoding="utf-8")
    return path
