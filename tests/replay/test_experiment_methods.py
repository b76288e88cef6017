"""Every method scored on the same bearings (synthetic bearings of the paper's arena)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.fusion import PAPER_N_L, PAPER_N_R
from pipeline.synthetic import PAPER_REFERENCE, simulate_bearings
from replay.experiments.methods import (
    RunContext,
    batch_ls_rows,
    crb_rows,
    estimator_rows,
    observations_from_summary,
)
from replay.experiments.results import ErrorRow
from replay.experiments.stats import per_run

SCORED = ["L3", "L4"]


def context(truth_fl: dict[str, np.ndarray], run: int) -> RunContext:
    return RunContext(
        group="t",
        run=run,
        landmarks=["L1", "L2", "L3", "L4"],
        reference=PAPER_REFERENCE,
        scored=SCORED,
        truth_fl=truth_fl,
        scale_cm=30.0,
        vision_error_rad=math.radians(3.0),
    )


def mean_by_movement(rows: list[ErrorRow]) -> dict[int, float]:
    moves = sorted({r.movement for r in rows})
    return {
        m: float(np.mean(list(per_run(r for r in rows if r.movement == m).values()))) for m in moves
    }


@pytest.mark.slow
def test_methods_fall_with_movements_and_respect_the_bound() -> None:
    rows: dict[str, list[ErrorRow]] = {"impartial": [], "mixture": [], "batch_ls": [], "crb": []}
    for run in range(6):
        sim = simulate_bearings(6, np.random.default_rng(100 + run))
        ctx = context(sim.truth_fl(), run)
        for prior in ("impartial", "mixture"):
            rows[prior] += estimator_rows(
                sim.observations,
                ctx,
                prior=prior,
                n_r=PAPER_N_R,
                n_l=PAPER_N_L,
                frame_change="sampled",
                rng=np.random.default_rng(run),
            )
        rows["batch_ls"] += batch_ls_rows(sim.observations, ctx)
        keyframes = list(zip(sim.o1_world, sim.o2_world, strict=True))
        sigma = math.radians(1.5)
        rows["crb"] += crb_rows(keyframes, sim.landmarks_world, ctx, sigma)
    for method, method_rows in rows.items():
        assert len(method_rows) == 6 * 6 * 2, method
        # a landmark not yet initialized (degenerate first movement) has no estimate (NaN)
        finite = [r for r in method_rows if math.isfinite(r.error_cm)]
        assert len(finite) >= 0.9 * len(method_rows), method
        assert all(math.isfinite(r.error_cm) for r in method_rows if r.movement == 6), method
        assert all(r.error_cm == pytest.approx(30.0 * r.error_fl) for r in finite)
        curve = mean_by_movement(method_rows)
        assert curve[6] < curve[1], (method, curve)
    # the Gaussian-equivalent bound with known observers is below every estimator
    crb = mean_by_movement(rows["crb"])
    for method in ("impartial", "mixture", "batch_ls"):
        assert mean_by_movement(rows[method])[6] > crb[6]
    # credible regions exist for the particle methods only
    assert all(r.inside_80 is not None for r in rows["impartial"] if math.isfinite(r.error_cm))
    assert all(r.inside_80 is None for r in rows["batch_ls"] + rows["crb"])


def test_observations_from_summary_skips_unseen() -> None:
    summary = {
        "movements": [
            {"index": 4, "bearings_deg": {"L1": [90.0, None], "L2": [-45.0, 10.0]}},
        ]
    }
    (obs,) = observations_from_summary(summary)
    assert obs.index == 4
    assert obs.bearings_o1_rad == pytest.approx({"L1": math.pi / 2, "L2": -math.pi / 4})
    assert obs.bearings_o2_rad == pytest.approx({"L2": math.radians(10.0)})
