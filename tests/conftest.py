"""Shared test settings: a deterministic Hypothesis profile (same examples on every run), and how
the run is spread over the machine's cores (pytest-xdist, ``-n auto --dist loadgroup`` in
pyproject.toml).

Each test module runs in one worker, so a module's fixtures are built once. Modules that time
real processes or send real signals (``pytestmark = pytest.mark.xdist_group("processes")``)
share one worker: two of them never run at once. ``-s``, ``--pdb``, benchmarks and runs of
named test files use no workers (``-n 0`` does the same for any run, ``-n 2`` forces two).
"""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

settings.register_profile(
    "deterministic",
    derandomize=True,
    deadline=None,
    max_examples=60,
    suppress_health_check=[HealthCheck.too_slow],
    print_blob=True,
)
settings.load_profile("deterministic")

BENCH = Path(__file__).parent / "bench"


def pytest_xdist_auto_num_workers(config: pytest.Config) -> int | None:
    """No workers where they get in the way, else xdist's count (one per core).

    In the way: printed output (``-s``), benchmarks (timed one at a time; pytest-benchmark
    switches itself off under xdist), and runs of named files or tests (starting the workers
    costs more than they save).
    """
    here = config.invocation_params.dir
    paths = [(here / arg.split("::")[0]).resolve() for arg in config.args]
    if config.option.capture == "no" or any(path.is_relative_to(BENCH) for path in paths):
        return 0
    if paths and all(path.is_file() for path in paths):
        return 0
    return None


@pytest.hookimpl(tryfirst=True)  # before xdist reads the groups
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if item.get_closest_marker("xdist_group") is None:
            item.add_marker(pytest.mark.xdist_group(item.nodeid.split("::")[0]))
