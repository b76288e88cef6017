"""One run of an experiment: simulate a log, process it, score every method on its bearings.

:func:`run_one` is the picklable per-run function the pool (or Dask) calls. The log and its
summary stay on disk (``run_000.mcap``, ``run_000.summary.json``) for ``bslam replay``.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from replay.experiments.geometry import scored_landmarks
from replay.experiments.methods import (
    RunContext,
    batch_ls_rows,
    crb_rows,
    estimator_rows,
    joint_rows,
    observations_from_summary,
    summary_rows,
)
from replay.experiments.protocol import Protocol
from replay.experiments.results import ErrorRow
from replay.truth import truth_from_scenario

if TYPE_CHECKING:
    from replay.plan import MovementPlan


@dataclass(frozen=True)
class RunTask:
    """One run: its group and index, its seed, its scenario document and its log path."""

    group: str
    run: int
    seed: int
    scenario: dict[str, Any]
    log: str
    protocol: Protocol


@dataclass
class RunOutput:
    """The rows of one run and the seconds spent per stage."""

    rows: list[ErrorRow] = field(default_factory=list)
    seconds: dict[str, float] = field(default_factory=dict)


def run_one(task: RunTask) -> RunOutput:
    """Simulate, process and score one run (every method of ``task.protocol``)."""
    from replay.process import process_log
    from replay.records import MethodConfig

    proto = task.protocol
    out = RunOutput()
    log = Path(task.log)
    tick = time.perf_counter()
    simulate(task.scenario, log, seed=task.seed)
    out.seconds["simulate"] = time.perf_counter() - tick

    tick = time.perf_counter()
    method = MethodConfig(
        prior="impartial", n_r=proto.n_r, n_l=proto.n_l, seed=task.seed, estimator="paper"
    )
    summary = process_log(log, method, summary=log.with_suffix(".summary.json")).to_json()
    out.seconds["process"] = time.perf_counter() - tick

    tick = time.perf_counter()
    ctx = _context(task, summary)
    plan = read_log_plan(log)
    observations = [
        replace(o, turn_rad=plan.turns_rad.get(o.index), distance_m=plan.distances_m.get(o.index))
        for o in observations_from_summary(summary)
    ]
    seeds = np.random.SeedSequence(task.seed).spawn(len(proto.priors) + len(proto.n_l_values))
    for i, prior in enumerate(proto.priors):
        if prior == "impartial" and proto.frame_change == "sampled":
            out.rows += summary_rows(summary, ctx, n_l=proto.n_l)
            continue
        out.rows += estimator_rows(
            observations,
            ctx,
            prior=prior,
            n_r=proto.n_r,
            n_l=proto.n_l,
            frame_change=proto.frame_change,
            rng=np.random.default_rng(seeds[i]),
        )
    for j, n_l in enumerate(proto.n_l_values):
        if n_l == proto.n_l and "impartial" in proto.priors:
            continue
        out.rows += estimator_rows(
            observations[: proto.n_l_movements],
            ctx,
            prior="impartial",
            n_r=proto.n_r,
            n_l=n_l,
            frame_change=proto.frame_change,
            rng=np.random.default_rng(seeds[len(proto.priors) + j]),
        )
    out.seconds["methods"] = time.perf_counter() - tick
    tick = time.perf_counter()
    if proto.joint:
        rng = np.random.default_rng(np.random.SeedSequence(task.seed).spawn(1)[0])
        out.rows += joint_rows(
            observations,
            ctx,
            n_r=proto.n_r,
            n_l=proto.n_l,
            rng=rng,
            distance_prior_rel=proto.distance_prior,
        )
    out.seconds["joint"] = time.perf_counter() - tick
    tick = time.perf_counter()
    if proto.batch_ls:
        out.rows += batch_ls_rows(observations, ctx)
    if proto.crb:
        truth = truth_from_scenario(task.scenario, ctx.reference)
        keyframes = true_keyframes(plan)
        out.rows += crb_rows(keyframes, truth.landmarks_world, ctx, _sigma_rad(task))
    out.seconds["yardsticks"] = time.perf_counter() - tick
    return out


def simulate(scenario: dict[str, Any], log: Path, *, seed: int) -> None:
    """Simulate the run's scenario into ``log`` (the library call behind ``bslam simulate``).

    The scenario is written beside the log (``run_000.scenario.json``), so that the run can be
    simulated again with ``bslam simulate --scenario ... --seed``. A scenario that cannot be
    driven raises the simulator's one-line :class:`~data_schemas.errors.BslamError`.
    """
    from recorder.sim.scenario import scenario_from_dict
    from recorder.sim.simulate import simulate_to_file

    scenario_path = log.with_suffix(".scenario.json")
    scenario_path.write_text(json.dumps(scenario, indent=1) + "\n", encoding="utf-8")
    sim = scenario_from_dict(scenario, what=scenario_path.name).with_seed(seed)
    simulate_to_file(sim, log, source=scenario_path.name)


def read_log_plan(log: Path) -> MovementPlan:
    """The movement plan of a log (keyframes, commanded turns, driven distances, true poses)."""
    from data_schemas.mcap.open import open_log
    from replay.plan import read_plan

    with open_log(log) as opened:
        return read_plan(opened)


def true_keyframes(plan: MovementPlan) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """True (O1, O2) positions (m, world) of every complete movement of a simulated log."""
    out = []
    for index in sorted(plan.keyframes):
        phases = plan.keyframes[index]
        if "start" in phases and "end" in phases:
            o1, o2 = plan.true_position(phases["start"]), plan.true_position(phases["end"])
            if o1 is not None and o2 is not None:
                out.append((o1, o2))
    return out


def _context(task: RunTask, summary: dict[str, Any]) -> RunContext:
    doc = task.scenario
    reference = (doc["reference"][0], doc["reference"][1])
    truth = truth_from_scenario(doc, reference)
    return RunContext(
        group=task.group,
        run=task.run,
        landmarks=[lm["name"] for lm in doc["landmarks"]],
        reference=reference,
        scored=scored_landmarks(doc),
        truth_fl=truth.landmarks_fl(),
        scale_cm=100.0 * truth.to_fl.unit_m,
        vision_error_rad=math.radians(float(summary["method"]["vision_error_deg"])),
    )


def _sigma_rad(task: RunTask) -> float:
    """Std of the bearing error: the simulated noise (a Gaussian truncated at the vision error
    bound) plus the quantization of one panorama column (width / 2 pi columns per radian)."""
    from data_schemas.angles import truncated_normal_std

    cam = task.scenario["camera"]
    std = math.radians(float(cam.get("bearing_noise_deg", 0.0)))
    noise = truncated_normal_std(std, math.radians(float(task.scenario["vision_error_deg"])))
    column = 2.0 * math.pi / float(cam["width"])
    return math.sqrt(noise**2 + column**2 / 12.0)
