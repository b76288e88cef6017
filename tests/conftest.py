"""Shared test settings: a deterministic Hypothesis profile (same examples on every run), and how
the run is spread over the machine's cores (pytest-xdist, ``-n auto --dist loadscope`` in
pyproject.toml, with the work units chosen here).

Each test module is one work unit, run whole by one worker, so a module's fixtures are built
once. The modules that time real processes or send real signals (``PROCESS_MODULES``) make one
unit together: two of them never run at once. ``-s``, ``--pdb``, benchmarks and runs of
named test files use no workers (``-n 0`` does the same for any run, ``-n 2`` forces two).
"""

from __future__ import annotations

import os
import signal
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings
from xdist.remote import Producer
from xdist.scheduler import LoadScopeScheduling

settings.register_profile(
    "deterministic",
    derandomize=True,
    deadline=None,
    max_examples=60,
    suppress_health_check=[HealthCheck.too_slow],
    print_blob=True,
)
settings.load_profile("deterministic")

# A shell without job control starts background jobs with Ctrl-C ignored, and Python then never
# installs its KeyboardInterrupt handler; children inherit the ignore. The tests that send
# SIGINT to the CLI, the recorder and the fake robot need it delivered as a user's Ctrl-C is.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

BENCH = Path(__file__).parent / "bench"


#: Extras' packages a test module may import. Where one is missing (the lowest-versions run,
#: .ci/lowest.txt, installs no viewer or experiments extra) such a module is skipped, not an error.
OPTIONAL_PACKAGES = frozenset({"rerun", "pyarrow", "matplotlib", "dask", "distributed", "rosbags"})


class _ModuleOfExtras(pytest.Module):
    """A test module skipped whole when it imports an extra's package that is not installed."""

    def _getobj(self) -> object:
        try:
            return super()._getobj()
        except pytest.Collector.CollectError as exc:
            missing = exc.__cause__
            name = (missing.name or "") if isinstance(missing, ModuleNotFoundError) else ""
            if name.split(".")[0] in OPTIONAL_PACKAGES:
                why = f"needs {name}, an extra's package (not installed)"
                pytest.skip(why, allow_module_level=True)
            raise


def pytest_pycollect_makemodule(module_path: Path, parent: pytest.Collector) -> pytest.Module:
    return _ModuleOfExtras.from_parent(parent, path=module_path)


def pytest_configure(config: pytest.Config) -> None:
    """Compile each module of the project once per run, not once per worker and per subprocess.

    Where ``PYTHONDONTWRITEBYTECODE`` is set in the environment, every test worker and every
    ``bslam`` subprocess compiled the project's modules again: about 2 s per worker and a few
    tenths per subprocess. The controller, before its workers start, lets Python write bytecode
    as it does by default (``__pycache__`` beside the sources, ignored by git); the workers and
    subprocesses inherit that. (A ``PYTHONPYCACHEPREFIX`` outside the tree would also move the
    installed libraries' bytecode there, and a fresh run would compile them all: slower.)
    """
    if hasattr(config, "workerinput") or not sys.dont_write_bytecode:
        return
    os.environ.pop("PYTHONDONTWRITEBYTECODE", None)
    sys.dont_write_bytecode = False


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


#: Modules that start real processes or send real signals: run one after another in one worker.
PROCESS_MODULES = frozenset(
    {
        "tests/recorder/test_fake_khepera.py",
        "tests/replay/test_cli_record_signals.py",
        "tests/replay/test_live.py",
        "tests/replay/test_signals.py",
    }
)


class ModuleScheduling(LoadScopeScheduling):
    """xdist's scope scheduling with a test module as the scope (``PROCESS_MODULES`` as one).

    (xdist's own ``loadgroup`` marks are not honoured under pytest 9.2: it renames ``_nodeid``,
    which pytest no longer reads, so the groups were silently ignored.)
    """

    def _split_scope(self, nodeid: str) -> str:
        module = nodeid.split("::", 1)[0]
        return "processes" if module in PROCESS_MODULES else module


def pytest_xdist_make_scheduler(config: pytest.Config, log: Producer) -> LoadScopeScheduling | None:
    if config.getvalue("dist") != "loadscope":
        return None  # another --dist was asked for: xdist's own
    return ModuleScheduling(config, log)
