"""LogWriter: session first, lazy schemas/channels, validation, indexed output, streams."""

from __future__ import annotations

import base64
import io
import json
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.records import Chunk, Header, Metadata
from mcap.stream_reader import StreamReader

from data_schemas.codec import validate
from data_schemas.errors import LogError, SchemaError
from data_schemas.mcap.writer import LogWriter
from data_schemas.registry import SESSION_METADATA_NAME, TOPICS
from recorder.clock import VirtualClock
from recorder.timebase import EpochClock
from tests.mcap_reader import LogReader
from tests.recorder.samples import make_session_doc, sample_messages

#: the channels a recorder writes (``/pipeline/...`` are derived logs' channels)
RECORDED = {name: t for name, t in TOPICS.items() if not name.startswith("/pipeline/")}


def _write_all(output: Any, n: int = 5) -> list[tuple[str, dict[str, Any]]]:
    clock = EpochClock(VirtualClock())
    written = []
    with LogWriter(output, make_session_doc(), clock=clock) as log:
        for i in range(n):
            msgs = sample_messages(clock.monotonic_ns(), np.random.default_rng(i))
            for topic_name, msg in msgs.items():
                log.write(topic_name, msg)
                written.append((topic_name, msg))
            clock.sleep(0.2)
    return written


def test_round_trip_every_topic_validates(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    written = _write_all(path)
    with LogReader(path) as reader:
        assert reader.finished
        got = list(reader.messages())
        assert reader.session().landmark_names() == ["L1", "L2"]
    assert [(m.topic, m.decode()) for m in got] == written
    for m in got:
        validate(TOPICS[m.topic].schema, m.decode(), what=m.topic)
    assert {m.topic for m in got} == set(RECORDED)


def test_session_metadata_is_the_first_record(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    _write_all(path, n=1)
    records = list(StreamReader(str(path), emit_chunks=True).records)
    assert isinstance(records[0], Header)
    assert isinstance(records[1], Metadata) and records[1].name == SESSION_METADATA_NAME
    assert json.loads(records[1].metadata["json"]) == make_session_doc()
    assert any(isinstance(r, Chunk) for r in records[2:])


def test_indexed_file_for_mcap_reader(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    _write_all(path, n=3)
    with path.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        assert summary.statistics.message_count == 3 * len(RECORDED)
        schemas = {s.name for s in summary.schemas.values()}
        assert schemas == {t.schema for t in RECORDED.values()}
        assert all(s.encoding == "jsonschema" for s in summary.schemas.values())
        topics = [c.topic for c in summary.channels.values()]
        assert sorted(topics) == sorted(RECORDED)  # one channel per topic
        times = [m.log_time for _, _, m in reader.iter_messages(log_time_order=False)]
        assert times == sorted(times)


def test_writes_to_a_binary_stream() -> None:
    buf = io.BytesIO()
    written = _write_all(buf, n=2)
    buf.seek(0)
    with LogReader(buf) as reader:
        assert [m.decode() for m in reader.messages()] == [msg for _, msg in written]
    assert not buf.closed  # the caller's stream stays open


def test_log_time_is_clock_time_and_publish_time_the_stamp(tmp_path: Path) -> None:
    clock = EpochClock(VirtualClock())
    path = tmp_path / "a.mcap"
    with LogWriter(path, make_session_doc(), clock=clock) as log:
        msg = sample_messages(clock.monotonic_ns(), np.random.default_rng(0))["/log"]
        clock.sleep(2.0)
        log_time = log.write("/log", msg)
    with LogReader(path) as reader:
        (m,) = reader.messages()
    assert m.log_time_ns == log_time == clock.start_wall_ns + 2_000_000_000
    assert m.publish_time_ns == clock.start_wall_ns


def test_invalid_message_is_refused_and_not_written(tmp_path: Path) -> None:
    clock = EpochClock(VirtualClock())
    path = tmp_path / "a.mcap"
    with LogWriter(path, make_session_doc(), clock=clock) as log:
        bad = sample_messages(clock.monotonic_ns(), np.random.default_rng(0))["/robot/movement"]
        bad["phase"] = "middle"
        with pytest.raises(SchemaError, match=r"^/robot/movement: field 'phase'"):
            log.write("/robot/movement", bad)
        assert log.message_count == 0
    with LogReader(path) as reader:
        assert list(reader.messages()) == []


def test_schema_change_on_a_topic_is_refused(tmp_path: Path) -> None:
    clock = EpochClock(VirtualClock())
    raw = {
        "timestamp": {"sec": 1, "nsec": 0},
        "frame_id": "panorama",
        "width": 1,
        "height": 1,
        "encoding": "bgr8",
        "step": 3,
        "data": "AAAA",
    }
    with LogWriter(tmp_path / "a.mcap", make_session_doc(), clock=clock) as log:
        log.write("/camera/panorama", raw, schema="foxglove.RawImage")  # allowed image schema
        png = sample_messages(clock.monotonic_ns(), np.random.default_rng(0))["/camera/panorama"]
        with pytest.raises(SchemaError, match=r"already writes it as foxglove\.RawImage"):
            log.write("/camera/panorama", png)
        with pytest.raises(SchemaError, match="not allowed"):
            log.write("/log", raw, schema="foxglove.RawImage")


def test_unknown_topic_and_bad_session(tmp_path: Path) -> None:
    doc = make_session_doc()
    with (
        LogWriter(tmp_path / "a.mcap", doc, clock=VirtualClock()) as log,
        pytest.raises(LogError, match="unknown topic"),
    ):
        log.write("/nope", {})
    del doc["reference"]
    with pytest.raises(SchemaError, match="reference"):
        LogWriter(tmp_path / "b.mcap", doc, clock=VirtualClock())
    assert not (tmp_path / "b.mcap").exists()


def test_finish_is_idempotent_and_final(tmp_path: Path) -> None:
    log = LogWriter(tmp_path / "a.mcap", make_session_doc(), clock=VirtualClock())
    log.finish()
    log.finish()
    with pytest.raises(LogError, match="already finished"):
        log.write("/log", sample_messages(0, np.random.default_rng(0))["/log"])


def test_cannot_create_log_in_missing_folder(tmp_path: Path) -> None:
    with pytest.raises(LogError, match=r"^cannot create log .*missing"):
        LogWriter(tmp_path / "missing" / "a.mcap", make_session_doc(), clock=VirtualClock())


def test_chunks_bounded_in_size(tmp_path: Path) -> None:
    clock = EpochClock(VirtualClock())
    path = tmp_path / "a.mcap"
    with LogWriter(path, make_session_doc(), clock=clock, chunk_bytes=2000) as log:
        for i in range(20):
            msgs = sample_messages(clock.monotonic_ns(), np.random.default_rng(i))
            log.write("/camera/panorama", msgs["/camera/panorama"])
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    sizes = [c.uncompressed_size for c in summary.chunk_indexes]
    assert len(sizes) >= 10
    assert max(sizes) < 2000 + 4000  # one frame message (~2.1 kB) past the bound at most


def test_old_chunk_reaches_the_file_without_further_writes(tmp_path: Path) -> None:
    # the background thread closes a chunk once its oldest message is chunk_seconds old
    path = tmp_path / "a.mcap"
    log = LogWriter(path, make_session_doc(), clock=VirtualClock(), chunk_seconds=0.2)
    try:
        log.write("/log", sample_messages(0, np.random.default_rng(0))["/log"])
        deadline = time.monotonic() + 10.0
        count = 0
        while count == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
            with LogReader(path, allow_unfinished=True) as reader:
                assert not reader.finished
                count = sum(1 for _ in reader.messages())
        assert count == 1
        assert log.committed_count == 1
    finally:
        log.finish()


def test_bytes_in_base64_fields_are_encoded_by_the_writer(tmp_path: Path) -> None:
    clock = EpochClock(VirtualClock())
    path = tmp_path / "a.mcap"
    png = bytes(range(256)) * 3 + b"\x00"  # base64 padding, '+' and '/' all occur
    pixels = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3)
    stamp = {"sec": 1, "nsec": 2}
    with LogWriter(path, make_session_doc(), clock=clock) as log:
        log.write(
            "/camera/panorama",
            {"timestamp": stamp, "frame_id": "panorama", "format": "png", "data": png},
        )
        log.write(
            "/camera/panorama",
            {"timestamp": stamp, "frame_id": "panorama", "format": "png", "data": bytearray(b"")},
        )
    with LogReader(path) as reader:
        first, second = (m.decode() for m in reader.messages())
    assert first == {
        "timestamp": stamp,
        "frame_id": "panorama",
        "format": "png",
        "data": base64.b64encode(png).decode(),
    }
    assert second["data"] == ""
    raw = {
        "timestamp": stamp,
        "frame_id": "panorama",
        "width": 3,
        "height": 2,
        "encoding": "bgr8",
        "step": 9,
        "data": pixels.data.cast("B"),
    }
    with LogWriter(tmp_path / "b.mcap", make_session_doc(), clock=clock) as log:
        log.write("/camera/panorama", raw, schema="foxglove.RawImage")
    with LogReader(tmp_path / "b.mcap") as reader:
        (m,) = reader.messages()
    got = m.decode()
    validate("foxglove.RawImage", got)
    assert base64.b64decode(got.pop("data")) == pixels.tobytes()
    assert got == {k: v for k, v in raw.items() if k != "data"}


def test_bytes_are_refused_outside_base64_fields_and_still_validated(tmp_path: Path) -> None:
    clock = EpochClock(VirtualClock())
    with LogWriter(tmp_path / "a.mcap", make_session_doc(), clock=clock) as log:
        msg = sample_messages(clock.monotonic_ns(), np.random.default_rng(0))["/log"]
        with pytest.raises(SchemaError, match=r"^/log: field 'message': bytes given"):
            log.write("/log", {**msg, "message": b"hello"})
        frame = {"timestamp": {"sec": 1, "nsec": 0}, "format": "png", "data": b"x"}
        with pytest.raises(SchemaError, match=r"^/camera/panorama: .*frame_id"):
            log.write("/camera/panorama", frame)  # the other fields are still checked
        assert log.message_count == 0
