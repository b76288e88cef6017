"""Chunk compression: the schemes MCAP allows and getting a chunk's records back out of them.

One definition for the in-place reader (:mod:`data_schemas.mcap.index`) and the checking scan
(:mod:`data_schemas.mcap.scan`). Both decompressors release the GIL while they work, so chunks
can be unpacked on a second core.
"""

from __future__ import annotations

import lz4.frame  # type: ignore[import-untyped]
import zstandard

#: Chunk compressions MCAP defines (``""``: stored).
COMPRESSIONS = ("", "zstd", "lz4")


class DecompressionError(ValueError):
    """A compressed chunk's data does not decompress (to its stated size)."""


def decompress(compression: str, data: bytes | memoryview, size: int) -> bytes:
    """The records of a chunk compressed with ``compression`` (``size`` bytes uncompressed).

    Raises
    ------
    DecompressionError
        Unknown compression, damaged data, or a size other than ``size``.
    """
    try:
        if compression == "zstd":
            records: bytes = zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
        elif compression == "lz4":
            records = lz4.frame.decompress(data)
        elif compression == "":
            records = bytes(data)
        else:
            raise DecompressionError(f"unknown chunk compression {compression!r}")
    except (zstandard.ZstdError, RuntimeError, ValueError) as exc:
        if isinstance(exc, DecompressionError):
            raise
        raise DecompressionError(f"its {compression} data does not decompress ({exc})") from None
    if len(records) != size:
        raise DecompressionError(
            f"its {compression} data decompresses to {len(records)} bytes, not {size}"
        )
    return records
