"""What ``bslam info`` reports about a log, as data (:func:`log_summary`) and as lines.

A finished, indexed log is summarised from its summary section (statistics, chunk, metadata and
attachment indexes, and the metadata records they point to): a few reads whatever the log's
size, no chunk checked. Any other log, or any log with ``check``, by one checking pass of
:class:`data_schemas.mcap.scan.LogScan`: channels and their message counts, time range, chunks
and their compression, metadata and attachments wherever they lie, the state of the file
(finished and indexed, finished without an index, unfinished, corrupt) and every damaged
stretch with its time range and topics.
"""

from __future__ import annotations

import datetime
import json
import os
import stat
from dataclasses import dataclass

from mcap.exceptions import McapError
from mcap.records import Attachment, Channel, Message, Metadata

from data_schemas.errors import BslamError
from data_schemas.mcap.processable import indexed_metadata, read_summary
from data_schemas.mcap.read import corruption
from data_schemas.mcap.scan import Damage, LogScan
from data_schemas.registry import SESSION_METADATA_NAME
from data_schemas.session import session_from_metadata


@dataclass(frozen=True)
class ChannelSummary:
    """One channel of a log: topic, schema name and message count."""

    topic: str
    schema: str
    count: int


@dataclass(frozen=True)
class AttachmentSummary:
    """One attachment: name, media type, size in bytes, log time (ns)."""

    name: str
    media_type: str
    size: int
    log_time_ns: int


@dataclass(frozen=True)
class LogSummary:
    """What ``bslam info`` reports about a log.

    Attributes
    ----------
    name : str
        The file.
    state : str
        ``"finished"`` (footer, and no damage), ``"unfinished"`` (the file just ends, as when a
        recording is interrupted) or ``"corrupt"`` (damage anywhere else).
    indexed : bool
        A summary section with a CRC that matches (a chunked file: with chunk indexes).
    channels : list of ChannelSummary
        In order of first appearance; channels without messages included.
    message_count : int
        Readable messages (for a damaged log: those that check out or were salvaged).
    chunk_count : int
        Chunks read whole (CRC checked).
    compressions : tuple of str
        Compressions of those chunks (``"stored"`` for uncompressed).
    start_ns, end_ns : int or None
        First and last ``log_time`` (ns since the epoch), None for an empty log.
    metadata : dict
        Metadata records: name -> key/value map (first record of each name).
    attachments : list of AttachmentSummary
    damage : list of Damage
        Every damaged stretch, in file order (a cut-off end included).
    trailing_bytes : int
        Bytes after the last complete record (an interrupted chunk), 0 if none.
    checked : bool
        Every chunk was read and its CRC checked (False: summarised from the summary section).
    """

    name: str
    state: str
    indexed: bool
    channels: list[ChannelSummary]
    message_count: int
    chunk_count: int
    compressions: tuple[str, ...]
    start_ns: int | None
    end_ns: int | None
    metadata: dict[str, dict[str, str]]
    attachments: list[AttachmentSummary]
    damage: list[Damage]
    trailing_bytes: int
    checked: bool = True

    @property
    def finished(self) -> bool:
        """The log is finished and undamaged."""
        return self.state == "finished"

    @property
    def duration_s(self) -> float:
        """Time between the first and last message, seconds (0 for an empty log)."""
        if self.start_ns is None or self.end_ns is None:
            return 0.0
        return (self.end_ns - self.start_ns) / 1e9


def log_summary(source: str | os.PathLike[str], *, check: bool = False) -> LogSummary:
    """Summarise a log, finished, unfinished or damaged: from its summary section when it is
    finished and indexed and not ``check``, else by one checking pass (every CRC)."""
    if not check:
        indexed = _from_summary(source)
        if indexed is not None:
            return indexed
    with LogScan(source) as scan:
        counts: dict[int, int] = {}
        metadata: dict[str, dict[str, str]] = {}
        attachments: list[AttachmentSummary] = []
        order: list[int] = []
        start: int | None = None
        end: int | None = None
        for record in scan.records():
            if isinstance(record, Message):
                counts[record.channel_id] = counts.get(record.channel_id, 0) + 1
                t = record.log_time
                start = t if start is None else min(start, t)
                end = t if end is None else max(end, t)
            elif isinstance(record, Channel):
                order.append(record.id)
            elif isinstance(record, Metadata):
                metadata.setdefault(record.name, dict(record.metadata))
            elif isinstance(record, Attachment):
                attachments.append(
                    AttachmentSummary(
                        record.name, record.media_type, len(record.data), record.log_time
                    )
                )
        channels = []
        for channel_id in order:
            channel = scan.channels[channel_id]
            schema = scan.schemas.get(channel.schema_id)
            channels.append(
                ChannelSummary(
                    channel.topic, "" if schema is None else schema.name, counts.get(channel_id, 0)
                )
            )
        if corruption(scan.damage):
            state = "corrupt"
        elif not scan.finished or scan.damage:
            state = "unfinished"
        else:
            state = "finished"
        return LogSummary(
            name=scan.name,
            state=state,
            indexed=scan.has_summary,
            channels=channels,
            message_count=scan.messages,
            chunk_count=scan.chunks,
            compressions=tuple(sorted(c or "stored" for c in scan.compressions)),
            start_ns=start,
            end_ns=end,
            metadata=metadata,
            attachments=attachments,
            damage=list(scan.damage),
            trailing_bytes=scan.trailing_bytes,
        )


def _from_summary(source: str | os.PathLike[str]) -> LogSummary | None:
    """The summary of a finished log from its summary section alone (None: the file has no
    readable summary with statistics, channels and chunk indexes that count every message)."""
    name = os.fspath(source)
    try:
        if not stat.S_ISREG(os.stat(name).st_mode):
            return None  # a FIFO or a device: the checking pass says what it is
        with open(name, "rb") as file:
            summary = read_summary(file)
            stats = None if summary is None else summary.statistics
            if summary is None or stats is None or not summary.chunk_indexes:
                return None
            counts = stats.channel_message_counts
            if sum(counts.values()) != stats.message_count or set(counts) - set(summary.channels):
                return None
            metadata = indexed_metadata(file, summary)
    except (OSError, McapError, ValueError, KeyError, UnicodeDecodeError, EOFError):
        return None  # the checking pass says what is wrong
    if len(metadata) < len({m.name for m in summary.metadata_indexes}):
        return None
    channels = []
    for channel_id in sorted(summary.channels):
        channel = summary.channels[channel_id]
        schema = summary.schemas.get(channel.schema_id)
        channels.append(
            ChannelSummary(
                channel.topic, "" if schema is None else schema.name, counts.get(channel_id, 0)
            )
        )
    attachments = [
        AttachmentSummary(a.name, a.media_type, a.data_size, a.log_time)
        for a in summary.attachment_indexes
    ]
    empty = stats.message_count == 0
    return LogSummary(
        name=name,
        state="finished",
        indexed=True,
        channels=channels,
        message_count=stats.message_count,
        chunk_count=len(summary.chunk_indexes),
        compressions=tuple(sorted({c.compression or "stored" for c in summary.chunk_indexes})),
        start_ns=None if empty else stats.message_start_time,
        end_ns=None if empty else stats.message_end_time,
        metadata=metadata,
        attachments=attachments,
        damage=[],
        trailing_bytes=0,
        checked=False,
    )


def _when(t_ns: int | None) -> str:
    if t_ns is None:
        return "-"
    return datetime.datetime.fromtimestamp(t_ns / 1e9, tz=datetime.UTC).isoformat()


def _state_line(s: LogSummary) -> str:
    if s.state == "finished" and not s.checked:
        return "finished (indexed), from its summary: chunks not checked (--check reads them)"
    if s.state == "finished":
        return "finished (indexed)" if s.indexed else "finished (no index)"
    if s.state == "unfinished":
        return "UNFINISHED (recording was interrupted)"
    return f"CORRUPT ({len(corruption(s.damage))} damaged part(s), listed below)"


#: Source files of an imported session listed by name (the rest are counted).
_LISTED_FILES = 5


def _session_lines(metadata: dict[str, dict[str, str]]) -> list[str]:
    record = metadata.get(SESSION_METADATA_NAME)
    if record is None:
        return ["session: none (no 'bslam.session' metadata: not a bearing-slam recording?)"]
    try:
        session = session_from_metadata(record)
    except BslamError as exc:
        return [f"session: invalid ({exc})"]
    doc = session.doc
    cal = session.calibration
    catalog = ", ".join(
        lm.name if lm.label == lm.name else f"{lm.name} ({lm.label})" for lm in session.landmarks
    )
    made = f"software {doc['software_version']}, created {_when(doc['created_unix_ns'])}"
    source = session.provenance
    if source is not None:
        listed = source["files"][:_LISTED_FILES]
        files = ", ".join(f"{f['name']} (sha256 {f['sha256'][:12]}...)" for f in listed)
        more = len(source["files"]) - len(listed)
        files += f" and {more} more" if more else ""
        lines = [f"session: imported by the {source['kind']} importer from {files}, {made}"]
    else:
        robot = doc.get("robot")
        kind = "simulated" if session.simulated else "recorded"
        by = f" with {robot['model']} on {robot['port']}" if robot else ""
        lines = [f"session: {kind}{by}, {made}"]
    if cal is None:
        lines.append("camera: none (bearings from /sensor/bearings)")
    else:
        camera = doc["camera"]
        lines.append(
            f"camera: {camera['source']}, {cal.model} {cal.width}x{cal.height}, "
            f"{camera.get('encoding', '?')}, {camera.get('frame_rate_hz', '?')} Hz"
        )
    lines.append(
        f"landmarks: {catalog}; reference {session.reference[0]}, "
        f"{session.reference[1]}; vision error {doc['vision_error_deg']:g} deg"
    )
    if "truth" in doc:
        lines.append(f"truth: {doc['truth']['source']} (evaluation only)")
    return lines


def summary_lines(s: LogSummary) -> list[str]:
    """The report ``bslam info`` prints, line by line."""
    lines = [f"{s.name}: {_state_line(s)}", *_session_lines(s.metadata)]
    for name in sorted(set(s.metadata) - {SESSION_METADATA_NAME}):
        lines.append(f"metadata {name}: {json.dumps(s.metadata[name])}")
    for a in s.attachments:
        lines.append(f"attachment {a.name}: {a.media_type}, {a.size} bytes")
    chunks = f"{s.chunk_count} chunks" + (
        f" ({', '.join(s.compressions)})" if s.compressions else ""
    )
    lines.append(
        f"messages: {s.message_count} in {chunks}; start {_when(s.start_ns)}, "
        f"end {_when(s.end_ns)}, duration {s.duration_s:.3f} s"
    )
    width = max([len("topic")] + [len(c.topic) for c in s.channels])
    swidth = max([len("schema")] + [len(c.schema) for c in s.channels])
    lines.append(f"  {'topic':<{width}}  {'schema':<{swidth}}  count")
    lines += [f"  {c.topic:<{width}}  {c.schema:<{swidth}}  {c.count}" for c in s.channels]
    lines += [f"damaged: {d.describe()}" for d in s.damage]
    return lines
