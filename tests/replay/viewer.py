"""Marks of tests that need an extra (``viewer``: Rerun; ``experiments``: matplotlib, Dask and
Rerun) in modules that mostly do not: they are skipped where the extra is not installed (the
lowest-versions run, .ci/lowest.txt: Rerun 0.41 needs numpy >= 2)."""

from __future__ import annotations

import importlib.util

import pytest

HAS_VIEWER = importlib.util.find_spec("rerun") is not None
HAS_EXPERIMENTS = HAS_VIEWER and all(
    importlib.util.find_spec(m) is not None for m in ("matplotlib", "distributed")
)
needs_viewer = pytest.mark.skipif(
    not HAS_VIEWER, reason="Rerun (bearing-slam[viewer]) is not installed"
)
needs_experiments = pytest.mark.skipif(
    not HAS_EXPERIMENTS, reason="bearing-slam[experiments] is not installed"
)
