from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

from logfactory import write_log

#: Test modules that import Rerun (the ``viewer`` extra, which needs numpy >= 2): not collected
#: where it is not installed (the lowest-versions run, ci/lowest.txt); the header says so.
VIEWER_MODULES = [
    "test_alike_landmarks.py",
    "test_association_sim.py",
    "test_end_to_end.py",
    "test_experiment_outputs.py",
    "test_live.py",
    "test_rerun.py",
    "test_serve.py",
    "test_signals.py",
]
HAS_VIEWER = importlib.util.find_spec("rerun") is not None
collect_ignore = [] if HAS_VIEWER else VIEWER_MODULES


def pytest_report_header() -> str | None:
    if HAS_VIEWER:
        return None
    return f"rerun-sdk not installed: {len(VIEWER_MODULES)} viewer test modules not collected"


@pytest.fixture(scope="session")
def small_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished 3-movement log with two frames between keyframes."""
    return write_log(tmp_path_factory.mktemp("logs") / "small.mcap", between=2)
