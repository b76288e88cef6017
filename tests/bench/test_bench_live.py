"""Live mode: latency of a follower beside a recording, its CPU, and the recorder's throughput
with a follower attached.

* Latency: ``bslam simulate``'s record loop in one process at 1x and 4x real time (paper
  scenario, ``--speed``), the real follower (``bslam process LOG --follow``) in another. For
  each movement: from the moment the recorder has written its end keyframe (its progress
  callback, right after the ``/robot/movement`` end message) to the follower's line for that
  movement. The floor is the recorder's chunk period (0.5 s): a keyframe is readable only once
  its chunk is closed. 1x and 4x runs alternate.
* CPU of the follower process at 1x: total (imports included) over the session, and after its
  first movement line (steady state).
* Recorder throughput with and without a follower: the writer benchmark's case (176x255 PNG
  level 1 frames into ``/dev/shm`` with fsync) with a ``bslam process --follow`` process reading
  the same file, alternated with the same run alone; medians and their ratio.

Run: ``python -m pytest tests/bench/test_bench_live.py -s``.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from test_bench_writer import _doc, _panorama

from data_schemas.mcap.writer import LogWriter
from data_schemas.registry import IMAGE_SCHEMA
from recorder.clock import SystemClock
from recorder.frames import frame_message
from recorder.timebase import EpochClock

BSLAM = [sys.executable, "-m", "replay.cli"]
TICK_S = 1.0 / os.sysconf("SC_CLK_TCK")
RECORDER = """
import sys, time
from recorder.sim.scenario import builtin_scenario
from recorder.sim.simulate import SimSettings, simulate_to_file
scenario = builtin_scenario("paper").with_seed(int(sys.argv[3]))
def progress(p):
    print(p.movements - 1, time.monotonic(), flush=True)
simulate_to_file(scenario, sys.argv[1], settings=SimSettings(speed=float(sys.argv[2])),
                 progress=progress)
"""


@pytest.fixture
def out_dir(tmp_path: Path) -> Iterator[Path]:
    """A folder in memory (``/dev/shm``) if the system has one, else ``tmp_path``."""
    if not os.path.isdir("/dev/shm"):
        yield tmp_path
        return
    with tempfile.TemporaryDirectory(dir="/dev/shm") as folder:
        yield Path(folder)


def _cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) * TICK_S


def _follow_run(log: Path, speed: float, seed: int) -> tuple[list[float], float, float]:
    """One session followed live: (latencies s, follower CPU total / session, steady CPU)."""
    follower = subprocess.Popen(
        [*BSLAM, "process", str(log), "--follow", "--idle-timeout", "5"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    shown: dict[int, float] = {}
    first: list[tuple[float, float]] = []

    def read() -> None:
        assert follower.stderr is not None
        for line in follower.stderr:
            if ": movement " in line:
                shown[int(line.split(": movement ")[1].split()[0])] = time.monotonic()
                if not first:
                    first.append((time.monotonic(), _cpu_s(follower.pid)))

    reader = threading.Thread(target=read)
    reader.start()
    t0 = time.monotonic()
    recorder = subprocess.run(
        [sys.executable, "-c", RECORDER, str(log), str(speed), str(seed)],
        capture_output=True,
        text=True,
        check=True,
    )
    t_rec = time.monotonic() - t0
    written = {int(i): float(t) for i, t in (ln.split() for ln in recorder.stdout.splitlines())}
    _, status, usage = os.wait4(follower.pid, 0)
    t_end = time.monotonic()
    follower.returncode = os.waitstatus_to_exitcode(status)
    reader.join()
    assert follower.returncode == 0 and first and sorted(shown) == sorted(written)
    cpu = usage.ru_utime + usage.ru_stime
    steady = (cpu - first[0][1]) / (t_end - first[0][0])
    return [shown[i] - written[i] for i in written], cpu / t_rec, steady


def test_bench_follow_latency_and_cpu(out_dir: Path) -> None:
    latencies: dict[float, list[float]] = {1.0: [], 4.0: []}
    cpu: list[tuple[float, float]] = []
    for seed in range(3):
        for speed in (1.0, 4.0):
            for run in range(1 if speed == 1.0 else 2):
                log = out_dir / f"s{seed}_{speed:g}_{run}.mcap"
                got, total, steady = _follow_run(log, speed, seed * 10 + run)
                latencies[speed] += got
                if speed == 1.0:
                    cpu.append((total, steady))
                log.unlink()
    for speed, values in latencies.items():
        v = np.array(values)
        print(
            f"\nlatency at {speed:g}x ({len(v)} movements): median {np.median(v):.2f} s, "
            f"p90 {np.percentile(v, 90):.2f} s, max {v.max():.2f} s, min {v.min():.2f} s; "
            f"<= 1.5 s: {np.mean(v <= 1.5):.0%}"
        )
    c = np.array(cpu)
    print(
        f"follower CPU at 1x (paper, {len(c)} sessions): median {np.median(c[:, 0]):.2f} core "
        f"over the session (imports included), {np.median(c[:, 1]):.2f} core after the first "
        "movement"
    )


def _record(path: Path, image: np.ndarray, n: int) -> float:
    """Seconds to write ``n`` PNG level-1 frames the way ``bslam record`` does."""
    clock = EpochClock(SystemClock())
    doc = _doc(*image.shape[:2], "png")  # type: ignore[arg-type]
    t0 = time.perf_counter()
    with LogWriter(path, doc, clock=clock) as log:
        for _ in range(n):
            msg = frame_message(image, clock.monotonic_ns(), encoding="png", png_level=1)
            log.write("/camera/panorama", msg, schema=IMAGE_SCHEMA["png"])
    return time.perf_counter() - t0


def test_bench_recorder_throughput_with_a_follower(out_dir: Path) -> None:
    image = _panorama(176, 255)
    n = 3000  # a few seconds: several chunks for the follower to read
    alone: list[float] = []
    followed: list[float] = []
    for _ in range(5):
        path = out_dir / "alone.mcap"
        alone.append(n / _record(path, image, n))
        path.unlink()
        path = out_dir / "followed.mcap"
        follower = subprocess.Popen(
            [*BSLAM, "process", str(path), "--follow", "--idle-timeout", "3"],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        time.sleep(1.0)  # the follower has imported its modules and waits for the file
        followed.append(n / _record(path, image, n))
        _, err = follower.communicate(timeout=60)
        assert follower.returncode == 0 and "finished" in err, err
        path.unlink()
    a, f = float(np.median(alone)), float(np.median(followed))
    print(
        f"\nrecorder 176x255 png1: alone {a:.0f} frames/s, with a follower {f:.0f} frames/s "
        f"(ratio {f / a:.2f}; goal >= 1000 frames/s)"
    )
