"""``bslam experiment arenas``: the joint estimator against batch least squares on varied arenas.

Each run draws its own arena (:func:`pipeline.synthetic.random_arena`: up to 3 x 2 m, 2-4
landmarks beyond a random reference pair (six landmark colours), bearing noise 0-1.5 deg),
alternates the unwrapped (720 x 120) and omnidirectional (320 x 320) camera, simulates a real log
and scores every method on its bearings. The goals (issue "Every bearing counts"): mean final
error of the joint map at most 0.8x batch least squares; no landmark more than 5 cm and 3x worse
than least squares; every landmark least squares places is mapped; 80% regions hold the truth
75-85% of the time.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from data_schemas.colors import COLOR_NAMES
from pipeline.synthetic import random_arena
from replay.experiments.experiment import _config, run_all
from replay.experiments.protocol import Protocol
from replay.experiments.results import Results, write_results
from replay.experiments.run import RunTask

CAMERAS = (
    {"model": "unwrapped", "width": 720, "height": 120},
    {"model": "omni", "width": 320, "height": 320},
)


def arena_scenario(seed: int, camera: dict[str, Any], movements: int) -> dict[str, Any]:
    """A scenario document for one run: a random arena seen by ``camera``."""
    rng = np.random.default_rng(seed)
    arena = random_arena(rng, extra_landmarks=(2, len(COLOR_NAMES) - 2))
    w, h = arena.size_m
    pts = np.array(list(arena.landmarks_world.values()))
    for _ in range(1000):
        start = rng.uniform([0.1, 0.1], [w - 0.1, h - 0.1])
        if np.hypot(*(pts - start).T).min() > 0.12:
            break
    return {
        "description": f"random arena {w:.2f} x {h:.2f} m (seed {seed})",
        "arena": {"width": w, "height": h},
        "landmarks": [
            {"name": n, "x": x, "y": y, "color": COLOR_NAMES[i]}
            for i, (n, (x, y)) in enumerate(arena.landmarks_world.items())
        ],
        "reference": list(arena.reference),
        "camera": {**camera, "bearing_noise_deg": round(arena.bearing_noise_deg, 3)},
        "vision_error_deg": 3.0,
        "trajectory": {
            "start": [float(start[0]), float(start[1])],
            "moves": movements,
            "distance": list(arena.move_m),
            "seed": seed,
        },
    }


def goals(results: Results) -> dict[str, Any]:
    """The goal figures from the final movement's rows of every run."""
    final = max(r.movement for r in results.rows)
    rows: dict[tuple[str, int, str], dict[str, Any]] = {}
    for r in results.rows:
        if r.movement == final and r.method in ("joint", "batch_ls", "impartial", "crb"):
            rows.setdefault((r.group, r.run, r.landmark), {})[r.method] = r
    joint, ls, paper, crb, inside = [], [], [], [], []
    missing = worse = 0
    for cell in rows.values():
        b = cell.get("batch_ls")
        j = cell.get("joint")
        if b is None or not math.isfinite(b.error_cm):
            continue
        if j is None or not math.isfinite(j.error_cm):
            missing += 1
            continue
        joint.append(j.error_cm)
        ls.append(b.error_cm)
        p = cell.get("impartial")
        paper.append(p.error_cm if p is not None else math.nan)
        crb.append(cell["crb"].error_cm if "crb" in cell else math.nan)
        if j.inside_80 is not None:
            inside.append(j.inside_80)
        worse += j.error_cm > 5.0 and j.error_cm > 3.0 * b.error_cm
    means = {k: _mean(v) for k, v in (("joint", joint), ("batch_ls", ls), ("paper", paper))}
    return {
        "runs": len({(g, r) for g, r, _ in rows}),
        "landmarks_scored": len(joint),
        "mean_error_cm": {**means, "crb": _mean(crb)},
        "ratio_to_batch_ls": _ratio(means["joint"], means["batch_ls"]),
        "paper_ratio_to_batch_ls": _ratio(means["paper"], means["batch_ls"]),
        "worse_than_5cm_and_3x_ls": int(worse),
        "missing_where_ls_places": int(missing),
        "coverage_80": _mean([float(x) for x in inside]),
    }


def _mean(values: list[float]) -> float | None:
    """Mean of the finite values (None: none)."""
    finite = [v for v in values if math.isfinite(v)]
    return float(np.mean(finite)) if finite else None


def _ratio(a: float | None, b: float | None) -> float | None:
    return None if a is None or not b else a / b


def arenas_experiment(
    out_dir: Path,
    protocol: Protocol,
    *,
    workers: int = 1,
    scheduler: str | None = None,
    progress: bool = True,
    command: str = "",
) -> Results:
    """``protocol.runs`` random arenas; results file, goals (``goals.json``, returned in info)."""
    start = time.perf_counter()
    proto = replace(protocol, priors=("impartial",), n_l_values=())
    folder = out_dir / "runs" / "arenas"
    folder.mkdir(parents=True, exist_ok=True)
    tasks = []
    for i in range(proto.runs):
        seed = proto.seed + i
        doc = arena_scenario(seed, CAMERAS[i % 2], proto.movements)
        tasks.append(RunTask("arenas", i, seed, doc, str(folder / f"run_{i:03d}.mcap"), proto))
    records, rows, stages = run_all(
        tasks, workers=workers, scheduler=scheduler, progress=progress, desc="arena runs"
    )
    info = {"command": command, "workers": workers, "scheduler": scheduler, "stage_s": stages}
    config = _config(proto, tasks[0].scenario)  # the first run's; each run's is beside its log
    config["arenas"] = "random per run: runs/arenas/run_NNN.scenario.json"
    results = Results("arenas", config, records, rows, info)
    results.info["goals"] = goals(results)
    results.info["elapsed_s"] = round(time.perf_counter() - start, 2)
    write_results(results, out_dir)
    return results
