"""The byte layout of the MCAP records that bearing-slam reads and writes without the library.

One definition for the writer (:mod:`data_schemas.mcap.chunks`), the in-place reader
(:mod:`data_schemas.mcap.index`), the follower (:mod:`data_schemas.mcap.follow`) and the checking
scanner (:mod:`data_schemas.mcap.scan`).
All integers are little-endian (MCAP specification).
"""

from __future__ import annotations

import struct

#: The bytes that open and close every MCAP file.
MAGIC = bytes([137, 77, 67, 65, 80, 48, 13, 10])
#: Every record starts with its opcode and the length of its body.
RECORD_HEADER = struct.Struct("<BQ")
#: Message record up to its data: opcode, length, channel id, sequence, log and publish time.
MESSAGE_HEADER = struct.Struct("<BQHIQQ")
MESSAGE_FIELDS = MESSAGE_HEADER.size - RECORD_HEADER.size
#: Chunk record up to its records: start/end time, uncompressed size and CRC, compression
#: (empty string: stored), records length; the records of a stored chunk follow it.
STORED_CHUNK_HEADER = struct.Struct("<BQQQQIIQ")
#: Chunk body up to the compression string: start/end time, uncompressed size and CRC.
CHUNK_FIELDS = struct.Struct("<QQQI")
#: Message index body up to its entries: channel id, entries length in bytes.
INDEX_FIELDS = struct.Struct("<HI")
#: One message index entry: log time, offset of the message record in the chunk's records.
INDEX_ENTRY = struct.Struct("<QQ")
#: Footer record up to its CRC: opcode, length, summary start, summary offset start.
FOOTER_PREFIX = struct.Struct("<BQQQ")
