"""Benchmark: whole commands on long simulated logs (issue 31), not in the default run.

Each figure is a whole process (CPU = user + system, peak RSS, from ``os.wait4``), the command
and its yardstick alternated, medians over the rounds.

``test_process_against_decoding_every_frame``: ``bslam process`` on a 1,000-movement paper-arena
log (PNG frames) against the yardstick "read and decode every frame" of the same log (a
process that opens it as ``process`` does and decodes every ``/camera/panorama`` message).
Goals: at most 3x, and a peak RSS of at most 300 MiB.

``test_replay_save_against_process``: ``bslam replay --save`` against ``bslam process`` on a
100-movement log. Goal: at most 1.5x (CPU). ``replay --keyframes-only --save`` is measured in
the same rounds: like ``process`` it decodes only the keyframes, so its ratio is what Rerun
itself costs (import, logging, writing), apart from decoding and classifying every frame.

``test_info_on_a_1_gb_log``: ``bslam info`` on a finished ~1 GB log (bgr8 frames), against
``info --check`` (every chunk read). Goals: at most 0.3 s CPU and 60 MiB.

The logs are simulated once into ``$BSLAM_BENCH_CACHE`` (default: a temporary folder).
Run with ``python -m pytest tests/bench/test_bench_long_logs.py -s -n 0``.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
BSLAM = [sys.executable, "-m", "replay.cli"]

DECODE_EVERY_FRAME = """
import sys
from data_schemas.mcap.processable import ProcessableLog
from replay.stages import CAMERA_TOPIC, decode_image
with ProcessableLog(sys.argv[1]) as log:
    for msg in log.messages([CAMERA_TOPIC]):
        decode_image(msg.schema, msg.decode())
"""


def _measure(args: list[str]) -> tuple[float, float]:
    """CPU seconds (user + system) and peak RSS (MiB) of one whole process."""
    with tempfile.TemporaryFile() as err:  # a pipe could fill up and stall the command
        proc = subprocess.Popen(args, env=ENV, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)
        err.seek(0)
        assert proc.returncode == 0, (args, err.read().decode()[-2000:])
    return usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024


def _alternated(rounds: int, **commands: list[str]) -> dict[str, tuple[float, float]]:
    """Median CPU seconds and median peak RSS (MiB) per command, the commands alternated."""
    runs: dict[str, list[tuple[float, float]]] = {name: [] for name in commands}
    for _ in range(rounds):
        for name, args in commands.items():
            runs[name].append(_measure(args))
    return {
        name: (statistics.median(c for c, _ in r), statistics.median(m for _, m in r))
        for name, r in runs.items()
    }


@pytest.fixture(scope="module")
def cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = os.environ.get("BSLAM_BENCH_CACHE")
    path = Path(folder) if folder else tmp_path_factory.mktemp("long_logs")
    path.mkdir(parents=True, exist_ok=True)
    return path


def _log(cache: Path, moves: int, encoding: str) -> Path:
    out = cache / f"paper_{moves}_{encoding}.mcap"
    if out.exists():
        return out
    scenario = json.loads((ROOT / "recorder/sim/scenarios/paper.json").read_text())
    scenario["trajectory"]["moves"] = moves
    spec = cache / f"paper_{moves}.json"
    spec.write_text(json.dumps(scenario))
    subprocess.run(
        [*BSLAM, "simulate", "--scenario", str(spec), "--out", str(out), "--encoding", encoding],
        check=True,
        env=ENV,
        cwd=ROOT,
        capture_output=True,
    )
    return out


def test_process_against_decoding_every_frame(cache: Path, benchmark: Any) -> None:
    log = _log(cache, 1000, "png")
    got = _alternated(
        3,
        process=[*BSLAM, "process", str(log), "--summary", str(cache / "s_1000.json"), "--force"],
        decode=[sys.executable, "-c", DECODE_EVERY_FRAME, str(log)],
    )
    (cpu, rss), (floor, floor_rss) = got["process"], got["decode"]
    print(
        f"\n{log.name} ({log.stat().st_size / 2**20:.0f} MiB): process {cpu:.1f} s CPU, peak "
        f"{rss:.0f} MiB; read and decode every frame {floor:.1f} s, peak {floor_rss:.0f} MiB; "
        f"ratio {cpu / floor:.2f} (goal 3), peak RSS goal 300 MiB"
    )
    benchmark.extra_info.update(process_s=cpu, decode_s=floor, ratio=cpu / floor, rss_mib=rss)
    benchmark.pedantic(lambda: None, rounds=1, iterations=1)
    assert cpu <= 3.0 * floor
    assert rss <= 300.0


def test_replay_save_against_process(cache: Path, benchmark: Any) -> None:
    log = _log(cache, 100, "png")
    rrd = cache / "replay_100.rrd"
    got = _alternated(
        5,
        replay=[*BSLAM, "replay", str(log), "--save", str(rrd), "--force"],
        process=[*BSLAM, "process", str(log), "--summary", str(cache / "s_100.json"), "--force"],
        keyframes=[*BSLAM, "replay", str(log), "--keyframes-only", "--save", str(rrd), "--force"],
    )
    (cpu, _), (floor, _), (keys, _) = got["replay"], got["process"], got["keyframes"]
    print(
        f"\n{log.name}: replay --save {cpu:.2f} s CPU, process {floor:.2f} s; "
        f"ratio {cpu / floor:.2f} (goal 1.5); replay --keyframes-only --save {keys:.2f} s, "
        f"ratio {keys / floor:.2f}"
    )
    benchmark.extra_info.update(
        replay_s=cpu, process_s=floor, ratio=cpu / floor, keyframes_only_ratio=keys / floor
    )
    benchmark.pedantic(lambda: None, rounds=1, iterations=1)
    assert cpu <= 1.5 * floor


def test_info_on_a_1_gb_log(cache: Path, benchmark: Any) -> None:
    log = _log(cache, 1000, "bgr8")
    got = _alternated(
        5,
        info=[*BSLAM, "info", str(log)],
        check=[*BSLAM, "info", "--check", str(log)],
    )
    (cpu, rss), (full, full_rss) = got["info"], got["check"]
    print(
        f"\n{log.name} ({log.stat().st_size / 2**30:.2f} GiB): info {cpu:.2f} s CPU, peak "
        f"{rss:.0f} MiB (goals 0.3 s, 60 MiB); info --check {full:.2f} s, {full_rss:.0f} MiB"
    )
    benchmark.extra_info.update(info_s=cpu, info_mib=rss, check_s=full, check_mib=full_rss)
    benchmark.pedantic(lambda: None, rounds=1, iterations=1)
    assert cpu <= 0.3
    assert rss <= 60.0
