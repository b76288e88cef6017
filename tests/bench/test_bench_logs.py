"""Log I/O speed: our fast paths against the ``mcap`` library, alternated in the same run.

* reading: :class:`~data_schemas.mcap.processable.ProcessableLog` (each chunk a pass reads is
  checked, CRC and message index, before the pass yields anything; messages then read in place
  from the mapped file) against the unchecked in-place read (per message: seek, header, data;
  what ``process`` did before the checks: the goal is within 10% of it), all frames and every
  10th frame (how ``process`` reads keyframes), and against mcap's indexed reader; a zstd log,
  read by the checking scan, against mcap's reader;
* writing: :class:`~data_schemas.mcap.chunks.McapChunkWriter` against mcap's ``Writer``, stored
  and zstd chunks (time and size: the cost of ``--chunk-compression zstd``);
* recovering: :func:`~data_schemas.mcap.recover.recover_log` of a whole log against one pass of
  mcap's stream reader.

Each case is run ``ROUNDS`` times, the cases alternating; medians and ratios are printed.
Run: ``python -m pytest tests/bench/test_bench_logs.py -s``.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from data_schemas.calibration import UnwrappedCalibration
from data_schemas.mcap.chunks import McapChunkWriter
from data_schemas.mcap.index import LogIndex
from data_schemas.mcap.layout import MESSAGE_FIELDS, MESSAGE_HEADER
from data_schemas.mcap.processable import ProcessableLog
from data_schemas.mcap.read import LogReader
from data_schemas.mcap.recover import recover_log
from data_schemas.mcap.writer import LogWriter
from data_schemas.registry import IMAGE_SCHEMA, MESSAGE_ENCODING, SCHEMA_ENCODING, schema_json
from data_schemas.session import LandmarkSpec
from recorder.clock import VirtualClock
from recorder.frames import frame_message
from recorder.session import build_session_doc
from recorder.timebase import EpochClock

ROUNDS = 7
FRAMES = 1500
HEIGHT, WIDTH = 176, 255


def _frame(rng: np.random.Generator) -> np.ndarray:
    y, x = np.mgrid[0:HEIGHT, 0:WIDTH]
    image = np.stack([x * 255 // WIDTH, y * 255 // HEIGHT, (x + y) % 256], -1).astype(np.uint8)
    image = cv2.GaussianBlur(image, (5, 5), 0)
    noise = rng.integers(-3, 4, image.shape)
    return np.clip(image.astype(int) + noise, 0, 255).astype(np.uint8)


def _write(path: Path, encoding: str, compression: str) -> None:
    doc = build_session_doc(
        created_unix_ns=1_700_000_000_000_000_000,
        robot={
            "model": "khepera",
            "port": "-",
            "baudrate": 9600,
            "mm_per_pulse": 0.08,
            "wheel_base_m": 0.053,
        },
        camera_source="bench",
        calibration=UnwrappedCalibration(WIDTH, HEIGHT),
        frame_rate_hz=5.0,
        encoding=encoding,  # type: ignore[arg-type]
        landmarks=[LandmarkSpec("L1", "red"), LandmarkSpec("L2", "green")],
        reference=("L1", "L2"),
        vision_error_rad=0.05,
    )
    clock = EpochClock(VirtualClock())
    rng = np.random.default_rng(0)
    frames = [_frame(rng) for _ in range(8)]
    with LogWriter(path, doc, clock=clock, fsync=False, compression=compression) as log:
        for i in range(FRAMES):
            t = clock.monotonic_ns()
            frame = frame_message(frames[i % 8], t, encoding=encoding)  # type: ignore[arg-type]
            log.write("/camera/panorama", frame, schema=IMAGE_SCHEMA[encoding])  # type: ignore[index]
            log.write(
                "/robot/odometry",
                {
                    "timestamp": {"sec": t // 10**9, "nsec": t % 10**9},
                    "left_pulses": i,
                    "right_pulses": -i,
                },
            )
            clock.sleep(0.2)


@pytest.fixture(scope="module")
def folder() -> Iterator[Path]:
    shm = Path("/dev/shm")
    with tempfile.TemporaryDirectory(dir=shm if shm.is_dir() else None) as d:
        yield Path(d)


def _alternate(cases: dict[str, Callable[[], Any]]) -> dict[str, float]:
    times: dict[str, list[float]] = {name: [] for name in cases}
    for _ in range(ROUNDS):
        for name, fn in cases.items():
            start = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - start)
    return {name: statistics.median(t) for name, t in times.items()}


def _report(title: str, medians: dict[str, float], yardstick: str) -> None:
    print(f"\n{title} (median of {ROUNDS}, ratio to {yardstick})")
    for name, t in medians.items():
        print(f"  {name:<34} {1000 * t:9.1f} ms  x{t / medians[yardstick]:.3f}")


def _checked(path: Path) -> int:
    with ProcessableLog(path) as log:
        return sum(len(m.data) for m in log.messages())


def _unchecked(path: Path, publish_times_ns: set[int] | None = None) -> int:
    """The in-place read before chunks were checked: per message, seek, header, data."""
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
        assert summary is not None
        index = LogIndex.of(f, summary)
        assert index is not None
        total = 0
        for _, records_at, offset, _ in sorted(
            p for c in index.channel_ids for p in index._places[c]
        ):
            f.seek(records_at + offset)
            fields = MESSAGE_HEADER.unpack(f.read(MESSAGE_HEADER.size))
            if publish_times_ns is None or fields[5] in publish_times_ns:
                total += len(f.read(fields[1] - MESSAGE_FIELDS))
        return total


def _keyframes(path: Path, checked: bool) -> int:
    """Every 10th frame by publish time (how ``process`` reads keyframes)."""
    with ProcessableLog(path) as log:
        times = {m.publish_time_ns for m in log.messages(["/robot/odometry"])}
        keys = set(sorted(times)[::10])
        if checked:
            return sum(len(m.data) for m in log.messages(publish_times_ns=keys))
    return _unchecked(path, keys)


def _mcap(path: Path) -> int:
    with path.open("rb") as f:
        return sum(len(m.data) for _, _, m in make_reader(f).iter_messages(log_time_order=True))


def test_bench_read(folder: Path) -> None:
    stored, zstd = folder / "stored.mcap", folder / "zstd.mcap"
    _write(stored, "bgr8", "")
    _write(zstd, "bgr8", "zstd")
    assert _checked(stored) == _unchecked(stored) == _mcap(stored) == _checked(zstd)
    assert _keyframes(stored, True) == _keyframes(stored, False)
    medians = _alternate(
        {
            "in place, unchecked (before)": lambda: _unchecked(stored),
            "in place, CRC + index checked": lambda: _checked(stored),
            "mcap indexed reader": lambda: _mcap(stored),
            "every 10th frame, unchecked (before)": lambda: _keyframes(stored, False),
            "every 10th frame, checked": lambda: _keyframes(stored, True),
            "zstd log: checking scan": lambda: _checked(zstd),
            "zstd log: mcap indexed reader": lambda: _mcap(zstd),
        }
    )
    _report(f"read {FRAMES} bgr8 frames {WIDTH}x{HEIGHT}", medians, "in place, unchecked (before)")
    # reading every byte: the CRC costs about as much as the copy (reported, not asserted);
    # reading the keyframes, as process does, the goal is to stay within 10% of before
    full = medians["in place, CRC + index checked"] / medians["in place, unchecked (before)"]
    sparse = medians["every 10th frame, checked"] / medians["every 10th frame, unchecked (before)"]
    print(f"  checked / unchecked: every frame x{full:.2f}, every 10th frame x{sparse:.2f}")
    assert sparse <= 1.10, f"checked keyframe reading is {sparse:.2f}x the unchecked one"


def test_bench_write_and_recover(folder: Path) -> None:
    source = folder / "source.mcap"
    _write(source, "bgr8", "")
    with LogReader(source) as reader:
        messages = list(reader.messages())

    def ours(compression: str) -> Path:
        out = folder / f"ours{compression}.mcap"
        with out.open("wb") as f:
            w = McapChunkWriter(f, library="bench", compression=compression)
            w.start({})
            ids: dict[str, int] = {}
            for m in messages:
                if m.topic not in ids:
                    sid = w.add_schema(m.schema, SCHEMA_ENCODING, schema_json(m.schema))
                    ids[m.topic] = w.add_channel(m.topic, MESSAGE_ENCODING, sid)
                w.add_message(ids[m.topic], m.sequence, m.log_time_ns, m.publish_time_ns, [m.data])
                if w.pending_bytes >= 4 << 20:
                    w.close_chunk()
            w.finish()
        return out

    def library(compression: CompressionType) -> Path:
        out = folder / f"lib{compression.value}.mcap"
        with out.open("wb") as f:
            w = Writer(f, chunk_size=4 << 20, compression=compression)
            w.start()
            ids: dict[str, int] = {}
            for m in messages:
                if m.topic not in ids:
                    sid = w.register_schema(m.schema, SCHEMA_ENCODING, schema_json(m.schema))
                    ids[m.topic] = w.register_channel(m.topic, MESSAGE_ENCODING, sid)
                w.add_message(ids[m.topic], m.log_time_ns, m.data, m.publish_time_ns, m.sequence)
            w.finish()
        return out

    def stream_pass() -> int:
        with source.open("rb") as f:
            return sum(1 for _ in StreamReader(f).records)

    fixed = folder / "fixed.mcap"
    medians = _alternate(
        {
            "ours, stored chunks": lambda: ours(""),
            "mcap Writer, stored chunks": lambda: library(CompressionType.NONE),
            "ours, zstd chunks": lambda: ours("zstd"),
            "mcap Writer, zstd chunks": lambda: library(CompressionType.ZSTD),
            "recover whole log": lambda: recover_log(source, fixed, force=True),
            "mcap stream reader pass": stream_pass,
        }
    )
    _report(f"write {len(messages)} messages", medians, "mcap Writer, stored chunks")
    for name in ("", "zstd"):
        size = (folder / f"ours{name}.mcap").stat().st_size
        print(f"  size, ours {name or 'stored'}: {size / 1e6:.1f} MB")
