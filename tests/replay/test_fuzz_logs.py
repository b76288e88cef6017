"""200 seeded mutations of a small valid log through ``info``, ``process``, ``replay`` and
``recover``: one line on stderr for an error, a documented exit code, no hang over 5 s, nothing
under a final name unless complete, the input unchanged, no traceback, bounded memory.

Each command runs over every mutation in one process of its own (``fuzz_driver.py``: the
imports are paid once, each log gets a 5 s alarm). Outputs are checked with the ``mcap``
library's reader and ``json``, not with our own.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from itertools import pairwise as pairs
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader

from tests.hostile import mutate, run_bslam

ROOT = Path(__file__).resolve().parents[2]
MUTATIONS = 200
#: Exit codes the docs give each command (docs/replay.md, docs/recording.md).
EXIT_CODES = {"info": {0, 1}, "process": {0, 1}, "replay": {0, 1}, "recover": {0, 1, 3}}
#: Peak memory of one command on one hostile file (MiB).
PEAK_MIB = 300
#: The mutations re-run alone to measure their peak: those that raised the driver's the most.
WORST = 3


#: The arguments of each command for one log and an output folder (as fuzz_driver.py's).
_ARGS = {
    "info": lambda log, out: ["info", log],
    "recover": lambda log, out: ["recover", log, out / "fixed.mcap"],
    "process": lambda log, out: [
        "process",
        log,
        "--out",
        out / "d.mcap",
        "--summary",
        out / "s.json",
    ],
    "replay": lambda log, out: ["replay", log, "--save", out / "r.rrd", "--keyframes-only"],
}


def _finished_mcap(path: Path) -> bool:
    with path.open("rb") as f:
        try:
            summary = make_reader(f).get_summary()
        except Exception:  # any failure of the outside reader: not complete
            return False
    return summary is not None


def _complete(name: str, path: Path) -> bool:
    if name.endswith(".mcap"):
        return _finished_mcap(path)
    if name.endswith(".json"):
        return isinstance(json.loads(path.read_text()), dict)
    return path.stat().st_size > 0  # .rrd: Rerun's reader is checked in test_rerun.py


@pytest.fixture(scope="module")
def mutants(small_log: Path, tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    folder = tmp_path_factory.mktemp("mutants")
    data = small_log.read_bytes()
    paths = []
    for seed in range(MUTATIONS):
        path = folder / f"m{seed:03d}.mcap"
        path.write_bytes(mutate(data, seed))
        paths.append(path)
    return paths


@pytest.mark.slow
@pytest.mark.parametrize("command", sorted(EXIT_CODES))
def test_mutated_logs(mutants: list[Path], tmp_path: Path, command: str) -> None:
    digests = {p: hashlib.sha256(p.read_bytes()).hexdigest() for p in mutants}
    done = subprocess.run(
        [sys.executable, str(Path(__file__).parent / "fuzz_driver.py"), command, str(tmp_path)]
        + [str(p) for p in mutants],
        capture_output=True,
        text=True,
        timeout=30 + 6 * len(mutants),
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    *lines, peak = done.stdout.strip().splitlines()
    reports: list[dict[str, Any]] = [json.loads(line) for line in lines]
    assert len(reports) == len(mutants)
    problems = []
    for r in reports:
        out = tmp_path / Path(r["log"]).stem
        err = [line for line in r["stderr"].splitlines() if line.strip()]
        if r["traceback"] or r["hang"] or r["code"] not in EXIT_CODES[command]:
            problems.append(f"{r['log']}: code {r['code']}, hang {r['hang']}, {r['traceback']}")
        elif r["code"] == 1 and (len(err) != 1 or not err[0].startswith("Error: ")):
            problems.append(f"{r['log']}: exit 1 with stderr {err}")
        elif r["code"] == 3 and not err[-1].startswith("something was lost"):
            problems.append(f"{r['log']}: exit 3 with stderr {err}")
        for name in r["outputs"]:
            if r["code"] == 1 or name.startswith(".") or not _complete(name, out / name):
                problems.append(f"{r['log']}: {name} left after exit {r['code']}")
    assert not problems, "\n".join(problems[:20])
    assert all(hashlib.sha256(p.read_bytes()).hexdigest() == d for p, d in digests.items())
    # the driver's peak also holds what 200 runs in one process accumulate: the files that
    # raised it the most are run again, alone, and measured there
    steps = sorted(
        (
            (after["peak_mib"] - before["peak_mib"], after["log"])
            for before, after in pairs(reports)
        ),
        reverse=True,
    )
    by_name = {p.name: p for p in mutants}
    for _, name in steps[:WORST]:
        alone_out = tmp_path / f"alone-{name}"
        alone_out.mkdir()
        args = _ARGS[command](by_name[name], alone_out)
        _, _, alone = run_bslam(*args, cwd=tmp_path)
        assert alone <= PEAK_MIB, (name, alone)
    assert int(peak) > 0
