"""Benchmark: ``bslam process`` on a 10-movement, 4-landmark log, whole process.

Yardstick: a process that imports the same libraries (``replay.process`` and what it pulls in,
and ``gtsam``, which the default joint estimator loads when it is made) and reads the log (every
message, JSON-decoded), measured in the same run, the two alternated. Goal: process at most 1.5x
the yardstick;
``bslam replay --save`` (Rerun output) at most 1 s in total.
``test_replay_save_against_process_by_log_length``: ``replay --save`` against ``process`` at 10,
100 and 400 movements (issue 31: at most 1.5x CPU) and their marginal CPU per movement.
Run with ``python -m pytest tests/bench/test_bench_process.py``.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
ROUNDS = 7

YARDSTICK = """
import json, sys
import replay.process  # the same libraries as `bslam process`
import gtsam  # the default (joint) estimator's, loaded when it is made
from mcap.reader import make_reader
with open(sys.argv[1], "rb") as f:
    for _, _, message in make_reader(f).iter_messages(log_time_order=True):
        json.loads(message.data)
"""


def _run(args: list[str]) -> None:
    subprocess.run(args, check=True, env=ENV, capture_output=True, cwd=ROOT)


@pytest.fixture(scope="module")
def paper_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    log = tmp_path_factory.mktemp("bench") / "paper.mcap"
    _run(
        [
            sys.executable,
            "-m",
            "replay.cli",
            "simulate",
            "--scenario",
            "paper",
            "--out",
            str(log),
            "--seed",
            "7",
        ]
    )
    return log


RESULTS: dict[str, float] = {}


def _bench(benchmark: Any, name: str, args: list[str]) -> None:
    benchmark.pedantic(_run, args=(args,), rounds=ROUNDS, iterations=1, warmup_rounds=1)
    RESULTS[name] = statistics.median(benchmark.stats.stats.data)
    benchmark.extra_info["median_s"] = RESULTS[name]


def test_yardstick_import_and_read(benchmark: Any, paper_log: Path) -> None:
    _bench(benchmark, "yardstick", [sys.executable, "-c", YARDSTICK, str(paper_log)])


def test_process_whole_alternated_with_the_yardstick(paper_log: Path, tmp_path: Path) -> None:
    """The goal's own measure: process and yardstick alternated A B A B, ratio of each pair."""
    summary = tmp_path / "s.json"
    process = [
        sys.executable,
        "-m",
        "replay.cli",
        "process",
        str(paper_log),
        "--summary",
        str(summary),
        "--force",  # each round replaces the last one's output
    ]
    yardstick = [sys.executable, "-c", YARDSTICK, str(paper_log)]
    _run(process)  # warm-up: page cache, output file
    pairs = []
    for _ in range(ROUNDS * 2):
        times = []
        for args in (process, yardstick):
            start = time.perf_counter()
            _run(args)
            times.append(time.perf_counter() - start)
        pairs.append(times)
    process_s = statistics.median(p for p, _ in pairs)
    yard_s = statistics.median(y for _, y in pairs)
    ratio = statistics.median(p / y for p, y in pairs)
    print(
        f"\nprocess {process_s:.3f} s, yardstick {yard_s:.3f} s (medians of {len(pairs)} "
        f"alternated pairs), ratio of the pairs {ratio:.2f} (goal <= 1.5); "
        f"load average {os.getloadavg()[0]:.1f}"
    )


def test_replay_with_rerun_output(benchmark: Any, paper_log: Path, tmp_path: Path) -> None:
    rrd = tmp_path / "paper.rrd"
    _bench(
        benchmark,
        "replay",
        [
            sys.executable,
            "-m",
            "replay.cli",
            "replay",
            str(paper_log),
            "--save",
            str(rrd),
            "--force",
        ],
    )
    ratio = RESULTS["replay"] / RESULTS["yardstick"]
    benchmark.extra_info["ratio_to_yardstick"] = ratio
    print(
        f"\nreplay --save {RESULTS['replay']:.3f} s in total (goal <= 1 s), "
        f"ratio {ratio:.2f} to the yardstick"
    )


def test_replay_save_against_process_by_log_length(
    tmp_path_factory: pytest.TempPathFactory, benchmark: Any
) -> None:
    """``replay --save`` against ``process`` (issue 31: at most 1.5x CPU) at 10, 100 and 400
    movements (and 1,000 with ``BSLAM_BENCH_LONG=1``): paper-arena PNG logs of
    ``tests/bench/test_bench_long_logs.py`` (kept in ``$BSLAM_BENCH_CACHE``), whole processes
    alternated, 5 rounds, CPU medians; then each command's marginal CPU per movement between
    the two longest logs, whose ratio is where the ratio goes on long logs."""
    from tests.bench.test_bench_long_logs import BSLAM, _alternated, _log

    folder = os.environ.get("BSLAM_BENCH_CACHE")
    cache = Path(folder) if folder else tmp_path_factory.mktemp("by_length")
    cache.mkdir(parents=True, exist_ok=True)
    lengths = [10, 100, 400] + ([1000] if os.environ.get("BSLAM_BENCH_LONG") else [])
    cpu: dict[int, tuple[float, float]] = {}
    for moves in lengths:
        log = _log(cache, moves, "png")
        got = _alternated(
            5,
            replay=[*BSLAM, "replay", str(log), "--save", str(cache / "by_length.rrd"), "--force"],
            process=[*BSLAM, "process", str(log), "--summary", str(cache / "s.json"), "--force"],
        )
        cpu[moves] = (got["replay"][0], got["process"][0])
        replay_s, process_s = cpu[moves]
        print(
            f"\n{moves} movements: replay --save {replay_s:.2f} s, process {process_s:.2f} s, "
            f"ratio {replay_s / process_s:.2f} (goal 1.5); load {os.getloadavg()[0]:.1f}"
        )
    a, b = lengths[-2], lengths[-1]
    per_replay = (cpu[b][0] - cpu[a][0]) / (b - a)
    per_process = (cpu[b][1] - cpu[a][1]) / (b - a)
    print(
        f"per movement ({a} -> {b}): replay --save {1e3 * per_replay:.1f} ms, process "
        f"{1e3 * per_process:.1f} ms, ratio {per_replay / per_process:.2f}"
    )
    benchmark.extra_info.update(
        {f"ratio_{m}": r / p for m, (r, p) in cpu.items()},
        marginal_ratio=per_replay / per_process,
    )
    benchmark.pedantic(lambda: None, rounds=1, iterations=1)
