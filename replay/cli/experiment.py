"""``bslam experiment``: the paper's experiment and parameter sweeps, on simulated logs."""

from __future__ import annotations

import os
import shlex
import sys
from pathlib import Path
from typing import Any

import click

from data_schemas.errors import BslamError
from replay import defaults
from replay.cli.options import SEED, distance_prior_option, n_l_option, n_r_option
from replay.experiments.protocol import (
    ALL_SWEEP_PARAMS,
    FRAME_CHANGES,
    PAPER_N_L_VALUES,
    ProtocolError,
    check_sweep_values,
)

DEFAULT_WORKERS = os.cpu_count() or 1


class ExperimentArgumentError(BslamError):
    """A command-line value of ``bslam experiment`` cannot be used."""


class NoRunSucceededError(BslamError):
    """Every run of an experiment failed."""


def _int_list(ctx: click.Context, param: click.Parameter, text: str) -> tuple[int, ...]:
    """``--n-l-values``: comma-separated particle counts of at least 2 (empty: none)."""
    try:
        values = tuple(int(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise click.BadParameter(
            f"expected comma-separated integers like 50,300,1000, got {text!r}"
        ) from None
    if any(v < 2 for v in values):
        raise click.BadParameter(f"particle counts must be at least 2, got {text!r}")
    return values


def _priors(ctx: click.Context, param: click.Parameter, text: str) -> tuple[str, ...]:
    """``--priors``: a comma-separated, non-empty subset of the prior names."""
    priors = tuple(p.strip() for p in text.split(",") if p.strip())
    unknown = [p for p in priors if p not in defaults.PRIORS]
    if unknown or not priors:
        raise click.BadParameter(
            f"expected a comma-separated list of {', '.join(defaults.PRIORS)}, got {text!r}"
        )
    return priors


def _out_dir(out: Path, force: bool) -> Path:
    """``--out``, checked before any work (including that it can be made)."""
    try:
        if out.exists() and not out.is_dir():
            raise ExperimentArgumentError(f"--out {out}: is a file; give a folder for the outputs")
        if out.is_dir() and any(out.iterdir()) and not force:
            raise ExperimentArgumentError(
                f"--out {out}: the folder holds earlier results; pass --force to replace them"
            )
        _can_make(out)
    except OSError as exc:
        raise ExperimentArgumentError(
            f"--out: cannot make the folder {str(out)[:200]}: {exc.strerror or exc}"
        ) from None
    return out


def _can_make(out: Path) -> None:
    """Make the folders missing on the way to ``out`` and remove them again (OSError if one
    cannot be made): the experiment makes them once every input has been validated."""
    missing = []
    for folder in (out, *out.parents):
        if folder.exists():
            break
        missing.append(folder)
    for folder in reversed(missing):
        folder.mkdir()
    for folder in missing:
        folder.rmdir()


def _common(fn: Any) -> Any:
    options = [
        click.option(
            "--out",
            type=click.Path(path_type=Path),
            required=True,
            help="Folder for logs, results, figures, .rrd and report.",
        ),
        click.option(
            "--runs", type=click.IntRange(min=1), default=None, help="Simulated trajectories."
        ),
        click.option(
            "--movements",
            type=click.IntRange(min=1),
            default=10,
            show_default=True,
            help="Straight movements per trajectory.",
        ),
        n_r_option,
        n_l_option,
        click.option(
            "--priors",
            default=",".join(defaults.PRIORS),
            show_default=True,
            callback=_priors,
            help="Single-view priors to compare.",
        ),
        click.option(
            "--frame-change",
            type=click.Choice(FRAME_CHANGES),
            default="sampled",
            show_default=True,
            help="sampled (O(n_l) random triples) or exact (all n_r^3 triples).",
        ),
        distance_prior_option,
        click.option(
            "--scenario",
            default="paper",
            show_default=True,
            help="Built-in scenario (paper, paper_omni, coded_3x2) or a scenario JSON file.",
        ),
        click.option(
            "--workers",
            type=click.IntRange(min=1),
            default=DEFAULT_WORKERS,
            show_default=True,
            help="Local worker processes.",
        ),
        click.option(
            "--scheduler",
            default=None,
            help="Dask scheduler address (tcp://host:8786) instead of local workers.",
        ),
        click.option(
            "--seed", type=SEED, default=0, show_default=True, help="Run i uses seed SEED + i."
        ),
        click.option("--quiet", is_flag=True, help="No progress bar."),
        click.option("--force", is_flag=True, help="Replace earlier results in --out."),
    ]
    for option in reversed(options):
        fn = option(fn)
    return fn


def _protocol(kw: dict[str, Any], runs: int, **extra: Any) -> Any:
    from replay.experiments.protocol import Protocol

    return Protocol(
        runs=runs,
        movements=kw["movements"],
        n_r=kw["n_r"],
        n_l=kw["n_l"],
        priors=kw["priors"],
        frame_change=kw["frame_change"],
        seed=kw["seed"],
        n_l_movements=min(3, kw["movements"]),
        distance_prior=kw["distance_prior"],
        **extra,
    )


def _needs_extras() -> None:
    """Fail early, before anything is written, if the experiments extra is missing."""
    from replay.extras import require

    require("matplotlib", extra="experiments", feature="bslam experiment")
    require("rerun", extra="experiments", feature="bslam experiment (its .rrd)")


@click.group("experiment")
def experiment() -> None:
    """Reproduce the paper's experiments and compare methods on simulated logs."""


@experiment.command("paper")
@_common
@click.option(
    "--n-l-values",
    default=",".join(str(n) for n in PAPER_N_L_VALUES),
    show_default=True,
    callback=_int_list,
    help="Particle counts of the Fig. 8 sweep (empty: skip it).",
)
def paper(**kw: Any) -> None:
    """The paper's protocol: 40 runs of 10 movements, Fig. 1/7/8, methods, report."""
    _needs_extras()
    from replay.experiments.experiment import paper_experiment, scenario_doc
    from replay.experiments.report import n_l_flatness, table_markdown

    proto = _protocol(kw, 40 if kw["runs"] is None else kw["runs"], n_l_values=kw["n_l_values"])
    scenario_doc(kw["scenario"])  # a bad scenario fails before the folder is made
    out = _out_dir(kw["out"], kw["force"])
    results = paper_experiment(
        out,
        proto,
        scenario=kw["scenario"],
        workers=kw["workers"],
        scheduler=kw["scheduler"],
        progress=not kw["quiet"],
        command=_command(),
    )
    _all_failed(results, out)
    _, spread = n_l_flatness(results)
    click.echo(table_markdown(results))
    if proto.n_l_values:
        click.echo(f"n_l sweep: spread {100 * spread:.0f}% of the mean error")
    _finish(results, out)


@experiment.command("sweep")
@_common
@click.option(
    "--param",
    type=click.Choice(ALL_SWEEP_PARAMS),
    required=True,
    help="The parameter to vary (n_landmarks: that many coded landmarks in the scenario's arena).",
)
@click.option("--values", required=True, help="Comma-separated values, e.g. 0.5,1,2.")
def sweep(**kw: Any) -> None:
    """Vary one parameter: one group of runs per value, a figure, a table per value."""
    _needs_extras()
    from replay.experiments.experiment import scenario_doc, sweep_experiment
    from replay.experiments.report import sweep_table_markdown

    values = [v.strip() for v in kw["values"].split(",") if v.strip()]
    try:
        check_sweep_values(kw["param"], values)
    except ProtocolError as exc:
        raise click.BadParameter(str(exc), param_hint="'--values'") from None
    proto = _protocol(kw, 10 if kw["runs"] is None else kw["runs"])
    scenario_doc(kw["scenario"])  # a bad scenario fails before the folder is made
    out = _out_dir(kw["out"], kw["force"])
    results = sweep_experiment(
        out,
        kw["param"],
        values,
        proto,
        scenario=kw["scenario"],
        workers=kw["workers"],
        scheduler=kw["scheduler"],
        progress=not kw["quiet"],
        command=_command(),
    )
    _all_failed(results, out)
    click.echo(sweep_table_markdown(results))
    _finish(results, out)


@experiment.command("arenas")
@_common
def arenas(**kw: Any) -> None:
    """Random arenas (up to 3 x 2 m, other reference pairs, both cameras, noise 0-1.5 deg):
    the joint estimator against batch least squares, the paper filter and the bound."""
    import json

    from replay.experiments.arenas import arenas_experiment

    proto = _protocol(kw, 100 if kw["runs"] is None else kw["runs"])
    out = _out_dir(kw["out"], kw["force"])
    results = arenas_experiment(
        out,
        proto,
        workers=kw["workers"],
        scheduler=kw["scheduler"],
        progress=not kw["quiet"],
        command=_command(),
    )
    _all_failed(results, out)
    (out / "goals.json").write_text(json.dumps(results.info["goals"], indent=1) + "\n")
    click.echo(json.dumps(results.info["goals"], indent=1))
    failed = results.failed()
    for r in failed:
        click.echo(f"run {r.group}/{r.run} (seed {r.seed}) {r.status}", err=True)
    click.echo(f"{len(results.runs) - len(failed)}/{len(results.runs)} runs ok; {out}")


def _families(ctx: click.Context, param: click.Parameter, text: str) -> tuple[str, ...]:
    """``--families``: ``all``, or a comma-separated, non-empty subset of the family names."""
    from replay.experiments.families import FAMILIES

    if text.strip() == "all":
        return FAMILIES
    families = tuple(dict.fromkeys(f.strip() for f in text.split(",") if f.strip()))
    unknown = [f for f in families if f not in FAMILIES]
    if unknown or not families:
        raise click.BadParameter(
            f"expected all or a comma-separated list of {', '.join(FAMILIES)}, got {text!r}"
        )
    return families


@experiment.command("calibration")
@click.option(
    "--out",
    type=click.Path(path_type=Path),
    required=True,
    help="Folder for scores.jsonl, calibration.json and calibration.md.",
)
@click.option(
    "--families",
    default="all",
    show_default=True,
    callback=_families,
    help="Arena families (replay/experiments/families.py), comma-separated, or all.",
)
@click.option(
    "--runs", type=click.IntRange(min=1), default=40, show_default=True, help="Runs per family."
)
@click.option(
    "--seed", type=SEED, default=0, show_default=True, help="Run i of each family uses SEED + i."
)
@click.option(
    "--workers",
    type=click.IntRange(min=1),
    default=DEFAULT_WORKERS,
    show_default=True,
    help="Local worker processes.",
)
@click.option("--scheduler", default=None, help="Dask scheduler address (tcp://host:8786) instead.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
@click.option("--force", is_flag=True, help="Replace earlier results in --out.")
def calibration(**kw: Any) -> None:
    """Do the joint map's 80% regions hold the truth 80% of the time? Simulated logs of each
    arena family through bearing extraction, the joint estimator and batch least squares:
    coverage with a 90% bootstrap interval over runs, and the mean error against least squares."""
    from replay.experiments.calibration_experiment import calibration_experiment, table_markdown

    out = _out_dir(kw["out"], kw["force"])
    results = calibration_experiment(
        out,
        kw["families"],
        kw["runs"],
        kw["seed"],
        workers=kw["workers"],
        scheduler=kw["scheduler"],
        progress=not kw["quiet"],
        command=_command(),
    )
    for family, seed, why in results.failures:
        click.echo(f"{family} seed {seed}: {why}", err=True)
    total = len(kw["families"]) * kw["runs"]
    if len(results.failures) == total:
        family, seed, why = results.failures[0]
        raise NoRunSucceededError(
            f"no run succeeded: all {total} failed, e.g. {family} seed {seed}: {why}"
        )
    click.echo(table_markdown(results.families), nl=False)
    click.echo(
        f"{total - len(results.failures)}/{total} runs ok in {results.elapsed_s:.1f} s; "
        f"table: {out / 'calibration.md'}; every landmark: {out / 'scores.jsonl'}"
    )


def _command() -> str:
    return "bslam " + " ".join(shlex.quote(a) for a in sys.argv[1:])


def _all_failed(results: Any, out: Path) -> None:
    """Exit 1 when no run succeeded, with the first run's reason."""
    failed = results.failed()
    if failed and len(failed) == len(results.runs):
        first = failed[0]
        raise NoRunSucceededError(
            f"no run succeeded: all {len(failed)} failed, e.g. run {first.group}/{first.run} "
            f"(seed {first.seed}) {first.status}; every run is in {out / 'results.json'}"
        )


def _finish(results: Any, out: Path) -> None:
    failed = results.failed()
    for r in failed:
        click.echo(f"run {r.group}/{r.run} (seed {r.seed}) {r.status}", err=True)
    click.echo(
        f"{len(results.runs) - len(failed)}/{len(results.runs)} runs ok in "
        f"{results.info['elapsed_s']:.1f} s; report: {out / 'report.md'}; logs: {out / 'runs'}"
    )
