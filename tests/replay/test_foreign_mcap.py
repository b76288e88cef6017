"""Any valid MCAP is read: layouts other writers produce, checked against mcap's stream reader.

Each file holds the same bearing-slam session (the ``small_log`` fixture), rewritten with the
``mcap`` library or laid out by hand: unchunked, zstd and lz4 chunks, metadata after the chunks,
no summary, a summary without channels, attachments, a foreign channel beside ours. ``info``
must count what mcap's reference stream reader counts, and ``process`` must map the same as
from the original log.
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner
from mcap.records import Attachment, Channel, DataEnd, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, IndexType, Writer

from data_schemas.mcap.chunks import McapChunkWriter, serialise
from data_schemas.mcap.info import log_summary
from data_schemas.mcap.layout import MAGIC, RECORD_HEADER
from data_schemas.registry import MESSAGE_ENCODING, SCHEMA_ENCODING, schema_json
from replay.cli import cli
from tests.mcap_reader import LogReader

Layout = Callable[[Path, Path], None]


def _records(log: Path) -> tuple[dict[str, dict[str, str]], list[Any]]:
    with LogReader(log) as reader:
        return reader.metadata, list(reader.messages())


def _library(**options: Any) -> Layout:
    """Rewrite a log with mcap's own Writer (``options`` passed to it)."""
    attach = options.pop("attach", False)
    chatter = options.pop("chatter", False)

    def write(src: Path, dst: Path) -> None:
        metadata, messages = _records(src)
        with dst.open("wb") as f:
            w = Writer(f, **options)
            w.start(library="another writer")
            for name, values in metadata.items():
                w.add_metadata(name, values)
            channels: dict[str, int] = {}
            for m in messages:
                if m.topic not in channels:
                    sid = w.register_schema(m.schema, SCHEMA_ENCODING, schema_json(m.schema))
                    channels[m.topic] = w.register_channel(m.topic, MESSAGE_ENCODING, sid)
                w.add_message(
                    channels[m.topic], m.log_time_ns, m.data, m.publish_time_ns, m.sequence
                )
                if chatter:
                    if "/chatter" not in channels:
                        sid = w.register_schema("std_msgs/String", "ros2msg", b"string data")
                        channels["/chatter"] = w.register_channel("/chatter", "cdr", sid)
                    w.add_message(channels["/chatter"], m.log_time_ns, b"\x00\x01hi", m.log_time_ns)
            if attach:
                w.add_attachment(5, 6, "calibration.yaml", "text/yaml", b"fx: 1\n")
            w.finish()

    return write


def _metadata_after_chunks(src: Path, dst: Path) -> None:
    """Our chunk writer, with the metadata written after every chunk (as `mcap add metadata`)."""
    metadata, messages = _records(src)
    with dst.open("wb") as f:
        w = McapChunkWriter(f, library="hand-built")
        w.start({})
        channels: dict[str, int] = {}
        for i, m in enumerate(messages):
            if m.topic not in channels:
                sid = w.add_schema(m.schema, SCHEMA_ENCODING, schema_json(m.schema))
                channels[m.topic] = w.add_channel(m.topic, MESSAGE_ENCODING, sid)
            w.add_message(channels[m.topic], m.sequence, m.log_time_ns, m.publish_time_ns, [m.data])
            if i % 7 == 6:
                w.close_chunk()
        w.close_chunk()
        for name, values in metadata.items():
            w.add_metadata(name, values)
        w.finish()


LAYOUTS: dict[str, Layout] = {
    "unchunked": _library(use_chunking=False),
    "zstd": _library(compression=CompressionType.ZSTD, chunk_size=4096),
    "lz4": _library(compression=CompressionType.LZ4, chunk_size=4096),
    "metadata-after-chunks": _metadata_after_chunks,
    "no-summary": _library(
        index_types=IndexType.NONE,
        repeat_channels=False,
        repeat_schemas=False,
        use_statistics=False,
        use_summary_offsets=False,
        chunk_size=4096,
    ),
    "summary-without-channels": _library(
        compression=CompressionType.ZSTD, repeat_channels=False, chunk_size=4096
    ),
    "attachment": _library(attach=True, chunk_size=4096),
    "foreign-channel": _library(chatter=True, compression=CompressionType.NONE, chunk_size=8192),
}


def _reference_counts(path: Path) -> Counter[str]:
    """Messages per topic, as mcap's stream reader sees them."""
    topics: dict[int, str] = {}
    counts: Counter[str] = Counter()
    with path.open("rb") as f:
        for record in StreamReader(f).records:
            if isinstance(record, Channel):
                topics[record.id] = record.topic
            elif isinstance(record, Message):
                counts[topics[record.channel_id]] += 1
    return counts


@pytest.fixture(scope="module")
def original_doc(small_log: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    out = tmp_path_factory.mktemp("orig") / "s.json"
    result = CliRunner().invoke(cli, ["process", str(small_log), "--summary", str(out)])
    assert result.exit_code == 0, result.output
    doc: dict[str, Any] = json.loads(out.read_text())
    return doc


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_info_counts_agree_with_reference_reader(
    small_log: Path, tmp_path: Path, layout: str
) -> None:
    path = tmp_path / f"{layout}.mcap"
    LAYOUTS[layout](small_log, path)
    s = log_summary(path)
    assert {c.topic: c.count for c in s.channels} == dict(_reference_counts(path))
    assert s.state == "finished" and s.damage == []
    assert s.metadata == log_summary(small_log).metadata
    assert s.indexed == (layout != "no-summary")
    if layout == "attachment":
        assert [(a.name, a.media_type, a.size) for a in s.attachments] == [
            ("calibration.yaml", "text/yaml", 6)
        ]
    result = CliRunner().invoke(cli, ["info", str(path)])
    assert result.exit_code == 0, result.output
    expected_state = "finished (no index)" if layout == "no-summary" else "finished (indexed)"
    assert expected_state in result.output


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_process_maps_the_same_from_any_layout(
    small_log: Path, tmp_path: Path, layout: str, original_doc: dict[str, Any]
) -> None:
    path = tmp_path / f"{layout}.mcap"
    LAYOUTS[layout](small_log, path)
    out = tmp_path / "s.json"
    result = CliRunner().invoke(cli, ["process", str(path), "--summary", str(out)])
    assert result.exit_code == 0, result.output
    if layout == "foreign-channel":
        assert "channel /chatter (schema 'std_msgs/String') is not bearing-slam's" in result.output
    doc = json.loads(out.read_text())
    assert doc["landmarks"] == original_doc["landmarks"]
    assert doc["movements"] == original_doc["movements"]


def _hand_built(src: Path, dst: Path) -> None:
    """Records laid out by hand: private records, top-level messages, no summary, an
    attachment between messages, metadata last, and a footer that points at nothing."""
    metadata, messages = _records(src)
    parts = [MAGIC, serialise(Header(profile="", library="by hand"))]
    parts.append(RECORD_HEADER.pack(0x80, 5) + b"hello")  # a private record: skipped
    channels: dict[str, int] = {}
    for i, m in enumerate(messages):
        if m.topic not in channels:
            schema_id = channel_id = len(channels) + 1
            parts.append(
                serialise(
                    Schema(
                        id=schema_id,
                        name=m.schema,
                        encoding=SCHEMA_ENCODING,
                        data=schema_json(m.schema),
                    )
                )
            )
            parts.append(
                serialise(
                    Channel(
                        id=channel_id,
                        topic=m.topic,
                        message_encoding=MESSAGE_ENCODING,
                        schema_id=schema_id,
                        metadata={},
                    )
                )
            )
            channels[m.topic] = channel_id
        parts.append(
            serialise(
                Message(
                    channel_id=channels[m.topic],
                    sequence=m.sequence,
                    log_time=m.log_time_ns,
                    publish_time=m.publish_time_ns,
                    data=m.data,
                )
            )
        )
        if i == 3:
            parts.append(
                serialise(
                    Attachment(
                        log_time=1,
                        create_time=2,
                        name="note.txt",
                        media_type="text/plain",
                        data=b"hi",
                    )
                )
            )
    for name, values in metadata.items():
        parts.append(serialise(Metadata(name=name, metadata=values)))
    parts.append(RECORD_HEADER.pack(0x81, 0))  # an empty private record
    parts.append(serialise(DataEnd(data_section_crc=0)))
    parts.append(serialise(Footer(summary_start=0, summary_offset_start=0, summary_crc=0)) + MAGIC)
    dst.write_bytes(b"".join(parts))


def test_hand_built_layout(small_log: Path, tmp_path: Path, original_doc: dict[str, Any]) -> None:
    path = tmp_path / "hand.mcap"
    _hand_built(small_log, path)
    s = log_summary(path)
    assert {c.topic: c.count for c in s.channels} == dict(_reference_counts(path))
    assert s.state == "finished" and not s.indexed and s.chunk_count == 0
    assert [a.name for a in s.attachments] == ["note.txt"]
    out = tmp_path / "s.json"
    result = CliRunner().invoke(cli, ["process", str(path), "--summary", str(out)])
    assert result.exit_code == 0, result.output
    assert json.loads(out.read_text())["landmarks"] == original_doc["landmarks"]
    fixed = tmp_path / "fixed.mcap"
    rec = CliRunner().invoke(cli, ["recover", str(path), str(fixed)])
    assert rec.exit_code == 0, rec.output
    again = log_summary(fixed)
    assert again.indexed and again.message_count == s.message_count
    assert [a.name for a in again.attachments] == ["note.txt"]


def test_open_log_warns_of_a_foreign_channel_unless_told_not_to(
    small_log: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    import logging

    from data_schemas.mcap.open import open_log

    path = tmp_path / "chatter.mcap"
    LAYOUTS["foreign-channel"](small_log, path)
    expected = "chatter.mcap: channel /chatter (schema 'std_msgs/String') is not bearing-slam's"
    with caplog.at_level(logging.WARNING, logger="bslam.logs"):
        with open_log(path) as opened:
            assert "/chatter" not in opened.topics
        assert [r.getMessage() for r in caplog.records] == [f"{expected}: ignored"]
        caplog.clear()
        with open_log(path, warn=False) as opened:  # a second look: the run warns once
            assert "/chatter" not in opened.topics and opened.notes
        assert caplog.records == []
