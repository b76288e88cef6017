"""Chunk compression: the schemes MCAP allows and getting a chunk's records back out of them.

One definition for the in-place reader (:mod:`data_schemas.mcap.index`) and the checking scan
(:mod:`data_schemas.mcap.scan`). Both decompressors release the GIL while they work, so chunks
can be unpacked on a second core.

A chunk states its uncompressed size; that size is checked against :data:`MAX_CHUNK_BYTES`
before anything is decompressed, and the decompressor is never allowed to produce more than it
(a 1 KB zstd frame can inflate to gigabytes: a "bomb", or a chunk that lies about its size).
"""

from __future__ import annotations

import lz4.frame  # type: ignore[import-untyped]
import zstandard

#: Chunk compressions MCAP defines (``""``: stored).
COMPRESSIONS = ("", "zstd", "lz4")
#: The largest uncompressed chunk we unpack (bytes). Our recorder closes chunks at 4 MiB plus
#: one message; 64 MiB leaves room for a 4K raw frame while a hostile file stays bounded.
MAX_CHUNK_BYTES = 64 * 1024 * 1024


class DecompressionError(ValueError):
    """A compressed chunk's data does not decompress (to its stated size)."""


def decompress(compression: str, data: bytes | memoryview, size: int) -> bytes:
    """The records of a chunk compressed with ``compression`` (``size`` bytes uncompressed).

    At most ``size`` bytes are ever produced, and ``size`` is at most :data:`MAX_CHUNK_BYTES`.

    Raises
    ------
    DecompressionError
        Unknown compression, a stated size over the limit, damaged data, or a size other than
        ``size``.
    """
    if compression not in COMPRESSIONS:
        raise DecompressionError(f"unknown chunk compression {compression!r}")
    if size > MAX_CHUNK_BYTES:
        raise DecompressionError(
            f"it states {size} bytes uncompressed, over the limit of {MAX_CHUNK_BYTES}"
        )
    try:
        if compression == "zstd":
            records = _zstd(data, size)
        elif compression == "lz4":
            records = _lz4(data, size)
        else:
            records = bytes(data)
    except (zstandard.ZstdError, RuntimeError, ValueError, MemoryError) as exc:
        if isinstance(exc, DecompressionError):
            raise
        raise DecompressionError(f"its {compression} data does not decompress ({exc})") from None
    if len(records) != size:
        raise DecompressionError(
            f"its {compression} data decompresses to {len(records)} bytes, not {size}"
        )
    return records


def _zstd(data: bytes | memoryview, size: int) -> bytes:
    # a frame that states its content size is allocated at that size: check it first
    stated = zstandard.frame_content_size(data)
    if stated not in (-1, size):
        raise DecompressionError(f"its zstd frame holds {stated} bytes, not {size}")
    # a frame without a stated size grows up to max_output_size, never more
    records: bytes = zstandard.ZstdDecompressor().decompress(data, max_output_size=max(size, 1))
    return records


def _lz4(data: bytes | memoryview, size: int) -> bytes:
    unpacker = lz4.frame.LZ4FrameDecompressor()
    records: bytes = unpacker.decompress(data, max_length=size + 1)
    if len(records) > size or not unpacker.eof:
        raise DecompressionError(f"its lz4 data decompresses to more than {size} bytes")
    return records
