"""Rewrite whatever a log still holds into a new, finished and indexed log.

:func:`recover_log` feeds every record :class:`data_schemas.mcap.scan.LogScan` trusts (intact
chunks before and after damage, complete messages salvaged from cut or corrupt stored chunks,
top-level messages of unchunked files, metadata and attachments wherever they lie) into
:class:`data_schemas.mcap.chunks.McapChunkWriter`. Schemas, channels, message times, sequences
and data are kept as they were. The new file is written next to its final name and renamed into
place (:mod:`data_schemas.outputs`), so it never replaces its input or a file it links to.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass

from mcap.records import Attachment, Channel, Message, Metadata, Schema

from data_schemas.errors import LogError
from data_schemas.mcap.chunks import McapChunkWriter
from data_schemas.mcap.scan import Damage, LogScan
from data_schemas.outputs import OutputGuard

#: Chunk size of a recovered log.
_RECOVER_CHUNK_BYTES = 4 * 1024 * 1024
#: Exit codes of ``bslam recover``: nothing lost, something lost (nothing readable raises).
EXIT_COMPLETE = 0
EXIT_LOSSY = 3


@dataclass(frozen=True)
class RecoverReport:
    """What :func:`recover_log` kept and what it could not.

    Attributes
    ----------
    messages, chunks, channels, metadata, attachments : int
        Messages, chunks read whole, channels, metadata and attachment records written.
    damage : list of Damage
        What was damaged in the input (with what was salvaged from each part).
    was_finished : bool
        The input was already a finished, undamaged log.
    lost : bool
        Something may be missing or wrong in the output: a damaged chunk (its salvaged
        messages are complete records, but the chunk's CRC no longer vouches for them), a cut
        record, unreadable bytes, messages without a channel.
    """

    messages: int
    chunks: int
    channels: int
    metadata: int
    attachments: int
    damage: list[Damage]
    was_finished: bool
    lost: bool

    @property
    def exit_code(self) -> int:
        """0 when nothing was lost, 3 when something was."""
        return EXIT_LOSSY if self.lost else EXIT_COMPLETE

    def lines(self, broken: str, fixed: str) -> list[str]:
        """What to tell the user: the result, then one line per damaged part."""
        note = " (it was already finished: nothing to repair)" if self.was_finished else ""
        head = (
            f"recovered {self.messages} messages ({self.channels} channels, {self.chunks} whole "
            f"chunks, {self.metadata} metadata, {self.attachments} attachments) from "
            f"{broken}{note} into {fixed}"
        )
        lines = [head]
        for d in self.damage:
            kind = "lost" if d.loses_data else "rebuilt"
            lines.append(f"{kind}: {d.describe()}")
        if self.lost:
            lines.append("something was lost (see above): exit 3")
        return lines


def recover_log(
    broken: str | os.PathLike[str],
    fixed: str | os.PathLike[str],
    *,
    force: bool = False,
    progress: Callable[[int], object] | None = None,
) -> RecoverReport:
    """Rewrite every record of ``broken`` that checks out into a new indexed log ``fixed``.

    Parameters
    ----------
    broken, fixed : path
        Input and output; ``fixed`` must not be ``broken`` or a link to it.
    force : bool
        Replace an existing ``fixed`` (never the input).
    progress : callable, optional
        Called with the number of messages rewritten so far, after each one (a progress bar).

    Raises
    ------
    LogError
        Nothing could be read (no message, metadata or attachment), or ``fixed`` cannot be
        written (exists without ``force``, is the input, folder missing...).
    NotMcapError
        ``broken`` is not an MCAP file.
    """
    guard = OutputGuard(inputs=[broken], force=force)
    target = guard.claim(fixed, what="recovered log")
    with LogScan(broken) as scan, guard.writing(target) as out:
        writer = McapChunkWriter(out, library="bearing-slam recover")
        writer.start({})
        schema_ids: dict[int, int] = {}
        channel_ids: dict[int, int] = {}
        messages = metadata = attachments = 0
        for record in scan.records():
            if isinstance(record, Message):
                writer.add_message(
                    channel_ids[record.channel_id],
                    record.sequence,
                    record.log_time,
                    record.publish_time,
                    [record.data],
                )
                messages += 1
                if progress is not None:
                    progress(messages)
                if writer.pending_bytes >= _RECOVER_CHUNK_BYTES:
                    writer.close_chunk()
            elif isinstance(record, Schema):
                schema_ids[record.id] = writer.add_schema(record.name, record.encoding, record.data)
            elif isinstance(record, Channel):
                channel_ids[record.id] = writer.add_channel(
                    record.topic,
                    record.message_encoding,
                    schema_ids.get(record.schema_id, 0),
                    dict(record.metadata),
                )
            elif isinstance(record, Metadata):
                writer.add_metadata(record.name, dict(record.metadata))
                metadata += 1
            elif isinstance(record, Attachment):
                writer.add_attachment(record)
                attachments += 1
        if messages == metadata == attachments == 0 and (scan.damage or not scan.finished):
            if not scan.damage:  # the magic bytes and nothing else, or a header alone
                raise LogError(f"nothing readable in {scan.name}: it holds no records")
            raise LogError(
                f"nothing readable in {scan.name}: "
                + "; ".join(d.describe() for d in scan.damage[:3])
            )
        writer.finish()
        return RecoverReport(
            messages=messages,
            chunks=scan.chunks,
            channels=len(channel_ids),
            metadata=metadata,
            attachments=attachments,
            damage=list(scan.damage),
            was_finished=scan.finished and not scan.damage,
            lost=scan.lost_data,
        )
