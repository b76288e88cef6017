"""Following a log: the same result as offline processing, on stored and fresh logs."""

from __future__ import annotations

from pathlib import Path

import pytest
from viewer import needs_viewer

from data_schemas.errors import UnknownSchemaError
from data_schemas.mcap.follow import FollowedLog
from data_schemas.mcap.processable import ProcessableLog
from replay.process import process_log
from replay.records import MethodConfig
from replay.sinks.summary import SummarySink

REGRESS = Path(__file__).resolve().parents[1] / "data" / "regress"
METHOD = MethodConfig(n_l=150, seed=7)


@pytest.mark.parametrize("name", ["unwrapped", "omni", "degenerate", "occluded"])
def test_followed_finished_log_gives_the_offline_result(name: str) -> None:
    path = REGRESS / f"{name}.mcap"
    with ProcessableLog(path) as log:
        offline = process_log(log, METHOD).to_json()
    with FollowedLog(path, idle_timeout_s=2) as log:
        followed = process_log(log, METHOD).to_json()
        assert log.end == "finished"
    assert followed == offline
    assert any(m["status"] == "ok" for m in offline["movements"])


def test_followed_hand_made_log_gives_the_offline_result(small_log: Path) -> None:
    # every frame (the Rerun sink's view): frames between keyframes are decoded too
    class AllFrames(SummarySink):
        wants_all_frames = True

    docs = []
    for opener in (ProcessableLog, lambda p: FollowedLog(p, idle_timeout_s=2)):
        sink = AllFrames()
        with opener(small_log) as log:
            process_log(log, METHOD, extra_sinks=(sink,))
        docs.append(sink.document)
    assert docs[0] == docs[1]


def _reordered(source: Path, out: Path, shift: str, rename: dict[str, str] | None = None) -> Path:
    """``source`` with every /robot/movement message moved after the next frame (``"late"``)
    or before its own keyframe (``"early"``), by its log time; file order is log-time order.
    ``rename`` renames schemas."""
    from mcap.records import Channel, Message, Schema

    from data_schemas.mcap.chunks import McapChunkWriter
    from tests.mcap_reader import LogReader

    with LogReader(source) as reader:
        metadata = reader.metadata
        records = list(reader.raw_records())
    topics = {r.id: r.topic for r in records if isinstance(r, Channel)}
    messages = [r for r in records if isinstance(r, Message)]
    frames = sorted(m.log_time for m in messages if topics[m.channel_id] == "/camera/panorama")
    moved = []
    for m in messages:
        t = m.log_time
        if topics[m.channel_id] == "/robot/movement":
            later = [f for f in frames if f > t]
            if shift == "late" and later:
                t = later[0] + 1
            elif shift == "early":
                t = max(f for f in frames if f <= t) - 1
        moved.append((t, m))
    with out.open("wb") as f:
        writer = McapChunkWriter(f, library="test")
        writer.start(metadata)
        for r in records:
            if isinstance(r, Schema):
                writer.add_schema((rename or {}).get(r.name, r.name), r.encoding, r.data)
            elif isinstance(r, Channel):
                writer.add_channel(r.topic, r.message_encoding, r.schema_id)
        for t, m in sorted(moved, key=lambda p: p[0]):
            writer.add_message(m.channel_id, m.sequence, t, m.publish_time, [m.data])
        writer.finish()
    return out


@pytest.mark.parametrize("shift", ["late", "early"])
def test_movement_messages_out_of_the_recorders_order(
    small_log: Path, tmp_path: Path, shift: str
) -> None:
    # the recorder writes a movement message right after its keyframe; other writers may not
    expected = process_log(small_log, METHOD).to_json()
    log = _reordered(small_log, tmp_path / f"{shift}.mcap", shift)
    for opened in (ProcessableLog(log), FollowedLog(log, idle_timeout_s=2)):
        with opened:
            doc = process_log(opened, METHOD).to_json()
        assert doc["movements"] == expected["movements"]
        assert doc["landmarks"] == expected["landmarks"]
    assert sum(m["status"] == "ok" for m in expected["movements"]) >= 2


def test_followed_channel_with_an_unknown_schema_is_one_line(
    small_log: Path, tmp_path: Path
) -> None:
    log = _reordered(small_log, tmp_path / "odd.mcap", "none", {"bslam.Movement": "bslam.Nope"})
    with pytest.raises(UnknownSchemaError) as offline:
        ProcessableLog(log)
    with FollowedLog(log, idle_timeout_s=2) as opened, pytest.raises(UnknownSchemaError) as live:
        process_log(opened, METHOD)
    assert str(live.value) == str(offline.value)
    assert "/robot/movement has schema 'bslam.Nope'" in str(live.value)


@needs_viewer
def test_replay_follow_of_an_interrupted_log_saves_what_it_read(
    small_log: Path, tmp_path: Path
) -> None:
    from click.testing import CliRunner

    from replay.cli import cli

    data = small_log.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: data.rindex(b"\x0f")])  # up to the data end record: no footer
    rrd = tmp_path / "cut.rrd"
    args = ["replay", str(cut), "--follow", "--idle-timeout", "0.3", "--save", str(rrd)]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 1
    assert "cut.mcap has not grown for 0.3 s: stopped following after 1 chunk " in result.stderr
    assert "3/3 movements used" in result.stdout and rrd.stat().st_size > 0
