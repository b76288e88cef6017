"""Plan runs, run them (pool or Dask), collect the rows, render figures, .rrd and report.

:func:`paper_experiment` is ``bslam experiment paper``; :func:`sweep_experiment` is
``bslam experiment sweep``. Both keep every simulated log (and its summary) under
``DIR/runs/<group>/`` so that any run can be replayed in Rerun.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from replay.experiments import plots
from replay.experiments.geometry import describe, scored_landmarks
from replay.experiments.protocol import (
    PROTOCOL_PARAMS,
    Protocol,
    apply_protocol_param,
    apply_scenario_param,
    check_sweep_values,
)
from replay.experiments.report import write_report, write_sweep_report
from replay.experiments.results import CRB, Results, RunRecord, write_results
from replay.experiments.rrd import write_rrd
from replay.experiments.run import RunOutput, RunTask, run_one
from replay.parallel import run_tasks


def scenario_doc(name_or_path: str) -> dict[str, Any]:
    """A built-in scenario (``paper``, ``paper_omni``) or a scenario file, as a validated dict."""
    from recorder.sim.scenario import scenario_named

    return scenario_named(name_or_path).to_dict()


def methods_of(protocol: Protocol) -> list[str]:
    """The methods an experiment scores, in table order."""
    extra = (["joint"] if protocol.joint else []) + (["batch_ls"] if protocol.batch_ls else [])
    return [*protocol.priors, *extra, *([CRB] if protocol.crb else [])]


def plan_runs(
    protocol: Protocol, scenario: dict[str, Any], out_dir: Path, group: str
) -> list[RunTask]:
    """One task per run: its seed, its scenario (trajectory seed set) and its log path."""
    folder = out_dir / "runs" / group.replace("=", "_")
    folder.mkdir(parents=True, exist_ok=True)
    tasks = []
    for i in range(protocol.runs):
        seed = protocol.seed + i
        moves = scenario["trajectory"]["moves"]
        moves = protocol.movements if isinstance(moves, int) else moves[: protocol.movements]
        doc = dict(scenario, trajectory={**scenario["trajectory"], "seed": seed, "moves": moves})
        tasks.append(RunTask(group, i, seed, doc, str(folder / f"run_{i:03d}.mcap"), protocol))
    return tasks


def run_all(
    tasks: Sequence[RunTask],
    *,
    workers: int,
    scheduler: str | None,
    progress: bool,
    desc: str,
) -> tuple[list[RunRecord], list[Any], dict[str, float]]:
    """Run the tasks; return per-run records, all rows and the summed stage times (s)."""
    outcomes = run_tasks(
        run_one, tasks, workers=workers, scheduler=scheduler, desc=desc, progress=progress
    )
    records, rows = [], []
    stages: dict[str, float] = {}
    for task, outcome in zip(tasks, outcomes, strict=True):
        out: RunOutput | None = outcome.value
        status = "ok" if out is not None else f"failed: {outcome.error}"
        records.append(
            RunRecord(task.group, task.run, task.seed, task.log, status, round(outcome.seconds, 3))
        )
        if out is not None:
            rows += out.rows
            for stage, s in out.seconds.items():
                stages[stage] = stages.get(stage, 0.0) + s
    return records, rows, {k: round(v, 2) for k, v in stages.items()}


def _config(protocol: Protocol, scenario: dict[str, Any]) -> dict[str, Any]:
    return {
        "protocol": protocol.to_dict(),
        "scenario": scenario,
        "geometry": describe(scenario),
        "scored_landmarks": scored_landmarks(scenario),
        "methods": methods_of(protocol),
    }


def paper_experiment(
    out_dir: Path,
    protocol: Protocol,
    *,
    scenario: str = "paper",
    workers: int = 1,
    scheduler: str | None = None,
    progress: bool = True,
    command: str = "",
) -> Results:
    """The paper's experiment: runs, results file, Fig. 1/7/8, comparison, .rrd, report."""
    start = time.perf_counter()
    doc = scenario_doc(scenario)
    tasks = plan_runs(protocol, doc, out_dir, "paper")
    records, rows, stages = run_all(
        tasks, workers=workers, scheduler=scheduler, progress=progress, desc="paper runs"
    )
    info = {"command": command, "workers": workers, "scheduler": scheduler, "stage_s": stages}
    info["runs_s"] = round(time.perf_counter() - start, 2)
    results = Results("paper", _config(protocol, doc), records, rows, info)
    if not rows:  # every run failed: the results file says why, there is nothing to draw
        results.info["elapsed_s"] = round(time.perf_counter() - start, 2)
        write_results(results, out_dir)
        return results
    figures = render_paper(results, out_dir)
    results.info["elapsed_s"] = round(time.perf_counter() - start, 2)
    write_results(results, out_dir)
    write_report(results, out_dir, figures)
    return results


def render_paper(results: Results, out_dir: Path) -> dict[str, str]:
    """Draw the paper experiment's figures and .rrd; return caption -> PNG file name."""
    figures = {
        "Fig. 7: error on the scored landmarks vs movements": plots.fig7_movements(
            results, out_dir / "fig7_movements.png"
        ).name,
        "Methods compared on the same bearings": plots.comparison(
            results, out_dir / "methods.png"
        ).name,
    }
    if results.config["protocol"]["n_l_values"]:
        figures["Fig. 8: error vs n_l"] = plots.fig8_n_l(results, out_dir / "fig8_n_l.png").name
    figures["Fig. 1: single-view priors"] = fig1(results, out_dir / "fig1_priors.png").name
    write_rrd(results, out_dir / "experiment.rrd")
    return figures


def fig1(results: Results, path: Path) -> Path:
    """The three priors of one bearing (eps of the experiment), as in the paper's Fig. 1."""
    from replay.fig1 import fig1_data

    eps_rad = math.radians(float(results.config["scenario"]["vision_error_deg"]))
    fig = fig1_data(eps_rad, nx=240, ny=120, nr=80)
    ys = fig.ys[::-1]  # the plot's y axis points up
    densities = {name: d[::-1] for name, d in fig.densities.items()}
    return plots.fig1_priors(fig.xs, ys, densities, fig.r, fig.marginals, path)


def sweep_experiment(
    out_dir: Path,
    param: str,
    values: Sequence[str],
    protocol: Protocol,
    *,
    scenario: str = "paper",
    workers: int = 1,
    scheduler: str | None = None,
    progress: bool = True,
    command: str = "",
) -> Results:
    """One group of runs per value of ``param``; results, a sweep figure, table and report."""
    from recorder.sim.scenario import scenario_from_dict

    start = time.perf_counter()
    check_sweep_values(param, list(values))
    groups: list[tuple[str, Protocol, dict[str, Any]]] = []
    for value in values:  # every value is checked before any folder is made
        group = f"{param}={value}"
        proto, doc = protocol, None
        if param == "camera_model":
            doc = scenario_doc({"unwrapped": "paper", "omni": "paper_omni"}.get(value, value))
        elif param in PROTOCOL_PARAMS:
            proto = apply_protocol_param(protocol, param, value)
        else:
            doc = apply_scenario_param(scenario_doc(scenario), param, float(value))
            scenario_from_dict(doc, what=f"scenario with {group}")
        groups.append((group, replace(proto, n_l_values=()), doc or scenario_doc(scenario)))
    tasks: list[RunTask] = []
    for group, proto, doc in groups:
        tasks += plan_runs(proto, doc, out_dir, group)
    records, rows, stages = run_all(
        tasks, workers=workers, scheduler=scheduler, progress=progress, desc=f"sweep {param}"
    )
    config = _config(replace(protocol, n_l_values=()), scenario_doc(scenario))
    config.update(param=param, values=list(values))
    # every group's scored landmarks (n_landmarks changes them from group to group)
    scored = [n for t in tasks for n in scored_landmarks(t.scenario)]
    config["scored_landmarks"] = list(dict.fromkeys(scored))
    info = {"command": command, "workers": workers, "scheduler": scheduler, "stage_s": stages}
    results = Results(f"sweep of {param}", config, records, rows, info)
    results.info["elapsed_s"] = round(time.perf_counter() - start, 2)
    write_results(results, out_dir)
    if not rows:  # every run failed: the results file says why, there is nothing to draw
        return results
    final = results.config["protocol"]["movements"]
    early = min(results.config["protocol"]["n_l_movements"], final)
    name = plots.sweep(results, out_dir / f"sweep_{param}.png", sorted({early, final})).name
    write_sweep_report(results, out_dir, name)
    return results
