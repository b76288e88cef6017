"""``bslam experiment``: the paper's experiment and parameter sweeps, on simulated logs."""

from __future__ import annotations

import os
import shlex
import sys
from pathlib import Path
from typing import Any

import click

from data_schemas.errors import BslamError

DEFAULT_WORKERS = os.cpu_count() or 1


class ExperimentArgumentError(BslamError):
    """A command-line value of ``bslam experiment`` cannot be used."""


def _int_list(text: str, option: str) -> tuple[int, ...]:
    try:
        values = tuple(int(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise ExperimentArgumentError(
            f"{option}: expected comma-separated integers like 50,300,1000, got {text!r}"
        ) from None
    return values


def _out_dir(out: Path) -> Path:
    if out.exists() and not out.is_dir():
        raise ExperimentArgumentError(f"--out {out}: is a file; give a folder for the outputs")
    out.mkdir(parents=True, exist_ok=True)
    return out


def _common(fn: Any) -> Any:
    options = [
        click.option(
            "--out",
            type=click.Path(path_type=Path),
            required=True,
            help="Folder for logs, results, figures, .rrd and report.",
        ),
        click.option("--runs", type=int, default=None, help="Simulated trajectories."),
        click.option(
            "--movements",
            type=int,
            default=10,
            show_default=True,
            help="Straight movements per trajectory.",
        ),
        click.option(
            "--n-r",
            "n_r",
            type=int,
            default=50,
            show_default=True,
            help="Particles per landmark in FR.",
        ),
        click.option(
            "--n-l",
            "n_l",
            type=int,
            default=300,
            show_default=True,
            help="Particles per landmark in FL.",
        ),
        click.option(
            "--priors",
            default="impartial,gaussian,mixture",
            show_default=True,
            help="Single-view priors to compare.",
        ),
        click.option(
            "--frame-change",
            default="sampled",
            show_default=True,
            help="sampled (O(n_l) random triples) or exact (all n_r^3 triples).",
        ),
        click.option(
            "--scenario",
            default="paper",
            show_default=True,
            help="Built-in scenario (paper, paper_omni) or a scenario JSON file.",
        ),
        click.option(
            "--workers",
            type=int,
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
            "--seed", type=int, default=0, show_default=True, help="Run i uses seed SEED + i."
        ),
        click.option("--quiet", is_flag=True, help="No progress bar."),
    ]
    for option in reversed(options):
        fn = option(fn)
    return fn


def _protocol(kw: dict[str, Any], runs: int, **extra: Any) -> Any:
    from replay.experiments.protocol import Protocol

    priors = tuple(p.strip() for p in kw["priors"].split(",") if p.strip())
    return Protocol(
        runs=runs,
        movements=kw["movements"],
        n_r=kw["n_r"],
        n_l=kw["n_l"],
        priors=priors,
        frame_change=kw["frame_change"],
        seed=kw["seed"],
        n_l_movements=min(3, kw["movements"]),
        **extra,
    )


@click.group("experiment")
def experiment() -> None:
    """Reproduce the paper's experiments and compare methods on simulated logs."""


@experiment.command("paper")
@_common
@click.option(
    "--n-l-values",
    default="50,100,200,300,500,1000",
    show_default=True,
    help="Particle counts of the Fig. 8 sweep (empty: skip it).",
)
def paper(**kw: Any) -> None:
    """The paper's protocol: 40 runs of 10 movements, Fig. 1/7/8, methods, report."""
    from replay.experiments.experiment import paper_experiment
    from replay.experiments.report import n_l_flatness, table_markdown

    out = _out_dir(kw["out"])
    proto = _protocol(
        kw,
        40 if kw["runs"] is None else kw["runs"],
        n_l_values=_int_list(kw["n_l_values"], "--n-l-values"),
    )
    results = paper_experiment(
        out,
        proto,
        scenario=kw["scenario"],
        workers=kw["workers"],
        scheduler=kw["scheduler"],
        progress=not kw["quiet"],
        command=_command(),
    )
    _, spread = n_l_flatness(results)
    click.echo(table_markdown(results))
    if proto.n_l_values:
        click.echo(f"n_l sweep: spread {100 * spread:.0f}% of the mean error")
    _finish(results, out)


@experiment.command("sweep")
@_common
@click.option(
    "--param",
    required=True,
    help="bearing_noise_deg, vision_error_deg, movement_length_m, camera_model, "
    "frame_change or n_l.",
)
@click.option("--values", required=True, help="Comma-separated values, e.g. 0.5,1,2.")
def sweep(**kw: Any) -> None:
    """Vary one parameter: one group of runs per value, a figure, a table per value."""
    from replay.experiments.experiment import sweep_experiment
    from replay.experiments.report import sweep_table_markdown

    out = _out_dir(kw["out"])
    values = [v.strip() for v in kw["values"].split(",") if v.strip()]
    if not values:
        raise ExperimentArgumentError("--values: give at least one value, e.g. 0.5,1,2")
    proto = _protocol(kw, 10 if kw["runs"] is None else kw["runs"])
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
    click.echo(sweep_table_markdown(results))
    _finish(results, out)


@experiment.command("arenas")
@_common
def arenas(**kw: Any) -> None:
    """Random arenas (up to 3 x 2 m, other reference pairs, both cameras, noise 0-1.5 deg):
    the joint estimator against batch least squares, the paper filter and the bound."""
    import json

    from replay.experiments.arenas import arenas_experiment

    out = _out_dir(kw["out"])
    proto = _protocol(kw, 100 if kw["runs"] is None else kw["runs"])
    results = arenas_experiment(
        out,
        proto,
        workers=kw["workers"],
        scheduler=kw["scheduler"],
        progress=not kw["quiet"],
        command=_command(),
    )
    (out / "goals.json").write_text(json.dumps(results.info["goals"], indent=1) + "\n")
    click.echo(json.dumps(results.info["goals"], indent=1))
    failed = results.failed()
    for r in failed:
        click.echo(f"run {r.group}/{r.run} (seed {r.seed}) {r.status}", err=True)
    click.echo(f"{len(results.runs) - len(failed)}/{len(results.runs)} runs ok; {out}")


def _command() -> str:
    return "bslam " + " ".join(shlex.quote(a) for a in sys.argv[1:])


def _finish(results: Any, out: Path) -> None:
    failed = results.failed()
    for r in failed:
        click.echo(f"run {r.group}/{r.run} (seed {r.seed}) {r.status}", err=True)
    click.echo(
        f"{len(results.runs) - len(failed)}/{len(results.runs)} runs ok in "
        f"{results.info['elapsed_s']:.1f} s; report: {out / 'report.md'}; logs: {out / 'runs'}"
    )
