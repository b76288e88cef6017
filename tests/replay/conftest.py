from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

from logfactory import write_log


@pytest.fixture(scope="session")
def small_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished 3-movement log with two frames between keyframes."""
    return write_log(tmp_path_factory.mktemp("logs") / "small.mcap", between=2)
