"""PNG figures of an experiment, drawn from its results (matplotlib, no display needed).

Every figure is a function of a :class:`~replay.experiments.results.Results` (and, for Fig. 1,
of the prior densities), so the plots can be redrawn from a results file at any time.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from numpy.typing import NDArray

from replay.experiments.results import CRB, METHOD_LABELS, PAPER_ERROR_CM, Results
from replay.experiments.stats import Band, movement_curve, n_l_curve

METHOD_COLORS = {
    "impartial": "tab:blue",
    "gaussian": "tab:orange",
    "mixture": "tab:green",
    "joint": "tab:purple",
    "batch_ls": "tab:red",
    CRB: "black",
}


def _curve(ax: Axes, bands: dict[int, Band], label: str, color: str, *, fill: bool) -> None:
    xs = np.array(sorted(bands))
    mean = np.array([bands[x].mean for x in xs])
    ax.plot(xs, mean, "o-", color=color, label=label, markersize=4)
    if fill:
        lo = np.array([bands[x].lo for x in xs])
        hi = np.array([bands[x].hi for x in xs])
        ax.fill_between(xs, lo, hi, color=color, alpha=0.2, linewidth=0)


def _save(fig: Figure, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path


def fig7_movements(results: Results, path: Path) -> Path:
    """Fig. 7: mean error of each scored landmark vs movements (impartial, n_l), 80% bands."""
    cfg = results.config
    fig = Figure(figsize=(6.0, 4.0))
    ax = fig.add_subplot()
    colors = ("tab:blue", "tab:purple", "tab:cyan", "tab:brown")
    for i, name in enumerate(cfg["scored_landmarks"]):
        bands = movement_curve(
            results.rows, method="impartial", n_l=cfg["protocol"]["n_l"], landmarks=[name]
        )
        _curve(ax, bands, name, colors[i % len(colors)], fill=True)
    ax.axhline(PAPER_ERROR_CM, color="gray", linestyle=":", label="paper: about 2 cm")
    ax.set_xlabel("straight movements")
    ax.set_ylabel("error (cm)")
    ax.set_title(f"Fig. 7: impartial PDF, n_l = {cfg['protocol']['n_l']} (80% bands over runs)")
    ax.set_ylim(bottom=0.0)
    ax.legend()
    return _save(fig, path)


def fig8_n_l(results: Results, path: Path) -> Path:
    """Fig. 8: error after ``n_l_movements`` movements vs n_l, 80% bands over runs."""
    cfg = results.config
    movement = cfg["protocol"]["n_l_movements"]
    fig = Figure(figsize=(6.0, 4.0))
    ax = fig.add_subplot()
    bands = n_l_curve(
        results.rows, method="impartial", movement=movement, landmarks=cfg["scored_landmarks"]
    )
    _curve(ax, bands, "impartial PDF", METHOD_COLORS["impartial"], fill=True)
    ax.axhline(PAPER_ERROR_CM, color="gray", linestyle=":", label="paper: about 2 cm")
    ax.set_xlabel("n_l (particles per landmark in FL)")
    ax.set_ylabel(f"error after {movement} movements (cm)")
    ax.set_title("Fig. 8: sensitivity to n_l (80% bands over runs)")
    ax.set_ylim(bottom=0.0)
    ax.legend()
    return _save(fig, path)


def comparison(results: Results, path: Path) -> Path:
    """Mean error vs movements for every method, the Cramér–Rao bound as a dashed line."""
    cfg = results.config
    fig = Figure(figsize=(6.5, 4.2))
    ax = fig.add_subplot()
    for method in cfg["methods"]:
        n_l = cfg["protocol"]["n_l"] if method in cfg["protocol"]["priors"] else 0
        bands = movement_curve(
            results.rows, method=method, n_l=n_l, landmarks=cfg["scored_landmarks"]
        )
        if not bands:
            continue
        if method == CRB:
            xs = sorted(bands)
            ax.plot(xs, [bands[x].mean for x in xs], "--", color="black", label=METHOD_LABELS[CRB])
        else:
            _curve(ax, bands, METHOD_LABELS[method], METHOD_COLORS[method], fill=False)
    ax.set_xlabel("straight movements")
    ax.set_ylabel("mean error (cm)")
    ax.set_yscale("log")
    ax.set_title("Methods on the same bearings (mean over runs)")
    ax.legend()
    return _save(fig, path)


def fig1_priors(
    x_fr: NDArray[np.float64],
    y_fr: NDArray[np.float64],
    densities: dict[str, NDArray[np.float64]],
    r: NDArray[np.float64],
    range_marginals: dict[str, NDArray[np.float64]],
    path: Path,
) -> Path:
    """Fig. 1: each prior's density of one bearing, and their range marginals p(r).

    Parameters
    ----------
    x_fr, y_fr : ndarray, shape (W,), (H,)
        Grid axes (observer at the origin, bearing along +x).
    densities : dict of str -> ndarray, shape (H, W)
        Density of each prior on the grid.
    r : ndarray, shape (k,)
        Ranges of the marginals.
    range_marginals : dict of str -> ndarray, shape (k,)
        p(r) of each prior (the impartial PDF's is flat).
    path : Path
        PNG to write.
    """
    n = len(densities)
    fig = Figure(figsize=(3.6 * (n + 1), 3.2))
    for i, (name, dens) in enumerate(densities.items()):
        ax = fig.add_subplot(1, n + 1, i + 1)
        ax.pcolormesh(x_fr, y_fr, np.sqrt(dens / dens.max()), shading="auto", cmap="viridis")
        ax.set_title(METHOD_LABELS.get(name, name))
        ax.set_xlabel("x (movement lengths)")
        if i == 0:
            ax.set_ylabel("y")
    ax = fig.add_subplot(1, n + 1, n + 1)
    for name, marginal in range_marginals.items():
        ax.plot(r, marginal, color=METHOD_COLORS.get(name, "gray"), label=METHOD_LABELS[name])
    ax.set_xlabel("range r")
    ax.set_ylabel("p(r)")
    ax.set_title("range marginals")
    ax.legend(fontsize="small")
    return _save(fig, path)


def sweep(results: Results, path: Path, movements: Sequence[int]) -> Path:
    """Mean error vs the swept value, one panel per movement count, one line per method.

    The impartial PDF carries its 80% band over runs; the Cramér–Rao bound is a dashed line.
    """
    cfg = results.config
    values = cfg["values"]
    xs = np.arange(len(values))
    fig = Figure(figsize=(4.6 * len(movements), 4.0))
    axes = [fig.add_subplot(1, len(movements), k + 1) for k in range(len(movements))]
    for ax, movement in zip(axes, movements, strict=True):
        for method in cfg["methods"]:
            n_l = None if method in cfg["protocol"]["priors"] else 0
            bands = [
                movement_curve(
                    results.rows,
                    method=method,
                    n_l=n_l,
                    landmarks=cfg["scored_landmarks"],
                    group=f"{cfg['param']}={value}",
                ).get(movement)
                for value in values
            ]
            mean = [np.nan if b is None else b.mean for b in bands]
            if method == CRB:
                ax.plot(xs, mean, "--", color="black", label=METHOD_LABELS[CRB])
                continue
            ax.plot(xs, mean, "o-", color=METHOD_COLORS[method], label=METHOD_LABELS[method])
            if method == "impartial":
                lo = [np.nan if b is None else b.lo for b in bands]
                hi = [np.nan if b is None else b.hi for b in bands]
                ax.fill_between(xs, lo, hi, color=METHOD_COLORS[method], alpha=0.2, linewidth=0)
        ax.set_xticks(xs, [str(v) for v in values])
        ax.set_xlabel(cfg["param"])
        ax.set_title(f"after {movement} movements")
        ax.set_ylim(bottom=0.0)
    axes[0].set_ylabel("mean error (cm)")
    axes[0].legend(fontsize="small")
    fig.suptitle(f"Sweep of {cfg['param']} (impartial PDF: 80% band over runs)")
    return _save(fig, path)
