"""The records inside a stored MCAP chunk, read with the mcap library's public API only.

mcap's ``StreamReader`` splits chunks itself but does not offer that step on its own (its
``breakup_chunk`` is not part of the documented API), so tests that look inside one chunk read
the chunk's records as a stream of records with ``StreamReader(..., skip_magic=True)``: an
oracle that shares no code with ``data_schemas/mcap/``.
"""

from __future__ import annotations

import io
import zlib

from mcap.exceptions import EndOfFile
from mcap.records import Chunk, McapRecord
from mcap.stream_reader import StreamReader


def chunk_records(chunk: Chunk) -> list[McapRecord]:
    """The schema, channel and message records of a stored ``chunk``, in order.

    Raises
    ------
    ValueError
        The chunk is compressed, its records do not match its CRC, or the last one is cut short.
    """
    if chunk.compression:
        raise ValueError(f"a {chunk.compression} chunk: only stored chunks are read here")
    if chunk.uncompressed_crc and zlib.crc32(chunk.data) != chunk.uncompressed_crc:
        raise ValueError("the chunk's records do not match its CRC")
    stream = io.BytesIO(chunk.data)
    out: list[McapRecord] = []
    whole = 0  # bytes of the records read whole
    try:
        for record in StreamReader(stream, skip_magic=True).records:
            out.append(record)
            whole = stream.tell()
    except EndOfFile:
        if whole != len(chunk.data):
            raise ValueError(f"a record at byte {whole} of the chunk is cut short") from None
    return out
