"""Batch least squares (pipeline/batch_ls.py): the Jacobian it hands the solver against central
differences of its own residuals, and its fit of exact bearings against the truth."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
import scipy.optimize

import pipeline.batch_ls as batch_ls
from pipeline.synthetic import PAPER_REFERENCE, simulate_bearings


def _run(sigma_frac: float, seed: int) -> Any:
    return simulate_bearings(
        6, np.random.default_rng(seed), eps_rad=math.radians(3.0), sigma_frac=sigma_frac
    )


def test_the_jacobian_matches_central_differences(monkeypatch: pytest.MonkeyPatch) -> None:
    seen: dict[str, Any] = {}
    solve = scipy.optimize.least_squares

    def spy(fun: Any, x0: Any, **kw: Any) -> Any:
        seen.update(fun=fun, jac=kw["jac"], x0=np.asarray(x0, np.float64))
        return solve(fun, x0, **kw)

    monkeypatch.setattr(scipy.optimize, "least_squares", spy)
    run = _run(0.5, 4)
    batch_ls.batch_least_squares(run.observations, list(run.landmarks_world), PAPER_REFERENCE)
    fun, jac, x0 = seen["fun"], seen["jac"], seen["x0"]
    rng = np.random.default_rng(0)
    for x in (x0, x0 + rng.normal(0.0, 0.05, x0.size)):
        h = 1e-6
        numeric = np.column_stack(
            [(fun(x + h * e) - fun(x - h * e)) / (2 * h) for e in np.eye(x.size)]
        )
        assert np.allclose(jac(x), numeric, atol=1e-5, rtol=1e-5)


def test_exact_bearings_give_the_true_layout() -> None:
    run = _run(1e-9, 7)
    truth = run.truth_fl(PAPER_REFERENCE)
    fit = batch_ls.batch_least_squares(run.observations, list(run.landmarks_world), PAPER_REFERENCE)
    assert sorted(fit) == ["L3", "L4"]
    for name, p in fit.items():
        assert np.hypot(*(p - truth[name])) < 1e-6, name
