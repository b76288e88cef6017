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

import os
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
from data_schemas.mcap.layout import MESSAGE_FIELDS, MESSAGE_HEADER, STORED_CHUNK_HEADER
from data_schemas.mcap.processable import ProcessableLog
from data_schemas.mcap.recover import recover_log
from data_schemas.mcap.writer import LogWriter
from data_schemas.registry import IMAGE_SCHEMA, MESSAGE_ENCODING, SCHEMA_ENCODING, schema_json
from data_schemas.session import LandmarkSpec
from recorder.clock import VirtualClock
from recorder.frames import frame_message
from recorder.session import build_session_doc
from recorder.timebase import EpochClock
from tests.mcap_reader import LogReader

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


_CPU: dict[str, float] = {}  # median process CPU time (all threads) of the last cases run
_CALLER: dict[str, float] = {}  # median CPU time of the calling thread alone


def _alternate(cases: dict[str, Callable[[], Any]]) -> dict[str, float]:
    times: dict[str, list[float]] = {name: [] for name in cases}
    cpu: dict[str, list[float]] = {name: [] for name in cases}
    caller: dict[str, list[float]] = {name: [] for name in cases}
    for _ in range(ROUNDS):
        for name, fn in cases.items():
            start, start_cpu = time.perf_counter(), time.process_time()
            start_caller = time.thread_time()
            fn()
            times[name].append(time.perf_counter() - start)
            cpu[name].append(time.process_time() - start_cpu)
            caller[name].append(time.thread_time() - start_caller)
    _CPU.clear()
    _CPU.update({name: statistics.median(t) for name, t in cpu.items()})
    _CALLER.clear()
    _CALLER.update({name: statistics.median(t) for name, t in caller.items()})
    return {name: statistics.median(t) for name, t in times.items()}


def _report(title: str, medians: dict[str, float], yardstick: str) -> None:
    print(
        f"\n{title} (median of {ROUNDS}, ratio to {yardstick}; CPU time of all threads and of "
        "the calling thread)"
    )
    for name, t in medians.items():
        cpu = f"  cpu {1000 * _CPU[name]:7.1f} ms" if name in _CPU else ""
        cpu += f", caller {1000 * _CALLER[name]:7.1f} ms" if name in _CALLER else ""
        print(f"  {name:<38} {1000 * t:9.1f} ms  x{t / medians[yardstick]:.3f}{cpu}")


def _checked(path: Path) -> int:
    with ProcessableLog(path) as log:
        return sum(len(m.data) for m in log.messages())


def _checks_off(path: Path) -> int:
    """The same reader with every chunk taken as checked: reading in place without the checks."""
    with ProcessableLog(path) as log:
        index = log._index
        assert index is not None
        index._checked.update(index._chunks)
        return sum(len(m.data) for m in log.messages())


def _unchecked(path: Path, publish_times_ns: set[int] | None = None) -> int:
    """The in-place read before chunks were checked: per message, seek, header, data."""
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
        assert summary is not None
        index = LogIndex.of(f, summary)
        assert index is not None
        total = 0
        for _, chunk_at, offset, _ in sorted(
            p for c in index.channel_ids for p in index._places[c]
        ):
            f.seek(chunk_at + STORED_CHUNK_HEADER.size + offset)
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


def _mcap(path: Path, validate_crcs: bool = False) -> int:
    """mcap's indexed reader (it checks no CRC unless asked)."""
    with path.open("rb") as f:
        reader = make_reader(f, validate_crcs=validate_crcs)
        return sum(len(m.data) for _, _, m in reader.iter_messages(log_time_order=True))


def _rewrite_lz4(source: Path, out: Path) -> None:
    """``source`` written again by mcap's ``Writer`` with lz4 chunks (ours writes zstd only)."""
    with source.open("rb") as f, out.open("wb") as o:
        writer = Writer(o, chunk_size=4 << 20, compression=CompressionType.LZ4)
        writer.start()
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        for record in reader.iter_metadata():
            writer.add_metadata(record.name, record.metadata)
        ids: dict[int, int] = {}
        for schema, channel, m in reader.iter_messages(log_time_order=False):
            if channel.id not in ids:
                sid = writer.register_schema(schema.name, schema.encoding, schema.data)
                ids[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, sid
                )
            writer.add_message(ids[channel.id], m.log_time, m.data, m.publish_time, m.sequence)
        writer.finish()


def test_bench_read(folder: Path) -> None:
    stored, zstd, lz4 = folder / "stored.mcap", folder / "zstd.mcap", folder / "lz4.mcap"
    _write(stored, "bgr8", "")
    _write(zstd, "bgr8", "zstd")
    _rewrite_lz4(stored, lz4)
    size = _checked(stored)
    assert size == _unchecked(stored) == _checks_off(stored) == _mcap(stored)
    assert size == _checked(zstd) == _mcap(zstd) == _checked(lz4) == _mcap(lz4)
    assert _keyframes(stored, True) == _keyframes(stored, False)
    medians = _alternate(
        {
            "in place, unchecked (before)": lambda: _unchecked(stored),
            "same reader, checks off": lambda: _checks_off(stored),
            "in place, CRC + index checked": lambda: _checked(stored),
            "mcap indexed reader": lambda: _mcap(stored),
            "mcap indexed reader, CRCs checked": lambda: _mcap(stored, True),
            "every 10th frame, unchecked (before)": lambda: _keyframes(stored, False),
            "every 10th frame, checked": lambda: _keyframes(stored, True),
            "zstd log: ours, checked": lambda: _checked(zstd),
            "zstd log: mcap indexed reader": lambda: _mcap(zstd),
            "zstd log: mcap, CRCs checked": lambda: _mcap(zstd, True),
            "lz4 log: ours, checked": lambda: _checked(lz4),
            "lz4 log: mcap indexed reader": lambda: _mcap(lz4),
            "lz4 log: mcap, CRCs checked": lambda: _mcap(lz4, True),
        }
    )
    _report(f"read {FRAMES} bgr8 frames {WIDTH}x{HEIGHT}", medians, "in place, unchecked (before)")
    ratio = {
        "every frame": medians["in place, CRC + index checked"]
        / medians["in place, unchecked (before)"],
        "every frame, to checks off": medians["in place, CRC + index checked"]
        / medians["same reader, checks off"],
        "every 10th frame": medians["every 10th frame, checked"]
        / medians["every 10th frame, unchecked (before)"],
        "zstd, to mcap": medians["zstd log: ours, checked"]
        / medians["zstd log: mcap indexed reader"],
        "zstd, to mcap checking CRCs": medians["zstd log: ours, checked"]
        / medians["zstd log: mcap, CRCs checked"],
        "lz4, to mcap": medians["lz4 log: ours, checked"] / medians["lz4 log: mcap indexed reader"],
        "lz4, to mcap checking CRCs": medians["lz4 log: ours, checked"]
        / medians["lz4 log: mcap, CRCs checked"],
    }
    print("  ratios: " + ", ".join(f"{k} x{v:.2f}" for k, v in ratio.items()))
    print(f"  load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    # the checks of a full read run on a second core: the ratio depends on one being free
    # (reported, not asserted); reading the keyframes, as process does, stays within 10%
    assert ratio["every 10th frame"] <= 1.10, (
        f"keyframe reading is x{ratio['every 10th frame']:.2f}"
    )


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
