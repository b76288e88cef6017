"""Hostile files for the fault-injection tests (bombs, lying chunks, deep nesting, mutations),
and :func:`run_bslam`, which runs a command on one in a process of its own.

Built with the ``mcap`` library's record classes and ``zstandard``/``lz4`` directly, not with
the project's writer, so a bug in our writer cannot hide the same bug in our reader.
"""

from __future__ import annotations

import os
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import lz4.frame  # type: ignore[import-untyped]
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.records import (
    Channel,
    DataEnd,
    Footer,
    Header,
    McapRecord,
    Message,
    Metadata,
    Schema,
)

MAGIC = b"\x89MCAP0\r\n"
ROOT = Path(__file__).resolve().parents[1]
#: Runs a command with a file-size limit (SIGXFSZ ignored: a write fails with EFBIG) and
#: prints its exit code and its peak memory (KiB), measured in this small launcher.
LAUNCHER = """
import resource, signal, subprocess, sys
limit = int(sys.argv[1])
def limited():
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    if limit:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
done = subprocess.run(sys.argv[2:], preexec_fn=limited)
peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
print(done.returncode, peak, file=sys.stderr)
"""


def run_bslam(
    *args: str | Path, limit: int = 0, cwd: Path | None = None, timeout: float = 60
) -> tuple[int, list[str], int]:
    """(exit code, stderr lines, peak MiB) of ``bslam args`` in a process of its own, with a
    file-size limit of ``limit`` bytes (0: none)."""
    done = subprocess.run(
        [sys.executable, "-c", LAUNCHER, str(limit), sys.executable, "-m", "replay.cli"]
        + [str(a) for a in args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=cwd,
        # under a file-size limit Python would leave truncated bytecode behind (its own writes
        # of __pycache__ ignore a short write)
        env={**os.environ, "PYTHONPATH": str(ROOT), "PYTHONDONTWRITEBYTECODE": "1"},
    )
    *lines, last = done.stderr.strip().splitlines()
    code, peak_kib = (int(v) for v in last.split())
    return code, [line for line in lines if line.strip()], peak_kib // 1024


def _record(record: McapRecord) -> bytes:
    builder = RecordBuilder()
    record.write(builder)
    data: bytes = builder.end()  # type: ignore[no-untyped-call]
    return data


def _chunk(records: bytes, compression: str, declared: int | None) -> bytes:
    """A chunk record by hand: ``declared`` replaces the true uncompressed size if given."""
    if compression == "zstd":
        payload = zstandard.ZstdCompressor(level=19).compress(records)
    elif compression == "lz4":
        payload = lz4.frame.compress(records)
    else:
        payload = records
    size = len(records) if declared is None else declared
    name = compression.encode()
    body = (
        struct.pack("<QQQI", 1, 1, size, zlib.crc32(records))
        + struct.pack("<I", len(name))
        + name
        + struct.pack("<Q", len(payload))
        + payload
    )
    return struct.pack("<BQ", 0x06, len(body)) + body


def session_json(small_log: Path) -> str:
    """The session metadata of a valid log (the ``bslam.session`` record's JSON)."""
    data = small_log.read_bytes()
    at = data.index(b"bslam.session")
    start = data.index(b"{", at)
    depth = 0
    for i in range(start, len(data)):
        depth += {ord("{"): 1, ord("}"): -1}.get(data[i], 0)
        if depth == 0:
            return data[start : i + 1].decode()
    raise ValueError("no session metadata")


def log_with_chunk(
    path: Path,
    session: str,
    payload: bytes,
    *,
    compression: str = "zstd",
    declared: int | None = None,
    topic: str = "/log",
    schema: str = "foxglove.Log",
    raw: bytes = b"",
) -> Path:
    """A finished (unindexed) log of one chunk holding one message of ``payload`` bytes.

    ``raw`` is appended to the chunk's records as it is (32 MiB of zeros: a bomb of empty
    records)."""
    records = (
        _record(Schema(id=1, name=schema, encoding="jsonschema", data=b"{}"))
        + _record(Channel(id=1, schema_id=1, topic=topic, message_encoding="json", metadata={}))
        + _record(Message(channel_id=1, sequence=1, log_time=1, publish_time=1, data=payload))
        + raw
    )
    path.write_bytes(
        MAGIC
        + _record(Header(profile="", library="hostile"))
        + _record(Metadata(name="bslam.session", metadata={"json": session}))
        + _chunk(records, compression, declared)
        + _record(DataEnd(data_section_crc=0))
        + _record(Footer(summary_start=0, summary_offset_start=0, summary_crc=0))
        + MAGIC
    )
    return path


def nested_text(depth: int) -> str:
    """JSON text nested ``depth`` lists deep."""
    return "[" * depth + "]" * depth


def mutate(data: bytes, seed: int) -> bytes:
    """One seeded mutation of ``data``: flipped bytes, a cut, a duplicated or zeroed span."""
    import random

    rng = random.Random(seed)
    out = bytearray(data)
    kind = rng.randrange(5)
    if kind == 0:  # flip a few bytes
        for _ in range(rng.randint(1, 8)):
            out[rng.randrange(len(out))] ^= 1 << rng.randrange(8)
    elif kind == 1:  # cut the file
        del out[rng.randrange(8, len(out)) :]
    elif kind == 2:  # zero a span
        at = rng.randrange(len(out))
        n = rng.randint(1, 512)
        out[at : at + n] = bytes(len(out[at : at + n]))
    elif kind == 3:  # duplicate a span elsewhere
        at = rng.randrange(len(out))
        n = rng.randint(1, 2048)
        span = out[at : at + n]
        to = rng.randrange(len(out))
        out[to:to] = span
    else:  # big-integer lengths: write 0xff over eight bytes
        at = rng.randrange(len(out) - 8)
        out[at : at + 8] = b"\xff" * 8
    return bytes(out)
