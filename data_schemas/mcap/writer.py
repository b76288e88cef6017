"""Crash-safe MCAP writer for bearing-slam logs.

:class:`LogWriter` writes the session metadata record first, then messages in chunks that it
closes itself, so that every byte it has accepted reaches the operating system soon:

* a chunk is closed when it holds ``chunk_bytes`` of messages, or when its oldest message is
  ``chunk_seconds`` old (real time). A background thread closes old chunks even while the
  recorder is blocked (waiting for the robot, say);
* closing a chunk writes it and its message indexes to the file in one ``write`` and flushes
  Python's buffer, so a killed process (SIGKILL) loses at most the open chunk: under one second
  of data;
* with ``fsync=True`` (the default for files) the background thread ``os.fsync``-s each closed
  chunk at once, so a power cut loses no more than a kill, while the recorder goes on encoding
  the next frame (``fsync`` of megabytes takes milliseconds);
* :meth:`LogWriter.finish` writes the summary and footer (an indexed file). An unfinished file
  is still readable chunk by chunk (:mod:`data_schemas.mcap.read`) and ``bslam recover`` indexes it.

If the disk fills up (``ENOSPC``, ``EDQUOT``, or ``EFBIG`` from ``RLIMIT_FSIZE``) the writer
cuts the file back to the end of the last complete chunk, stops, and raises
:class:`~data_schemas.errors.DiskFullError`.

Speed: the MCAP records are assembled by :class:`data_schemas.mcap.chunks.McapChunkWriter` without
intermediate copies, and a field that the schema declares ``contentEncoding: base64`` (image
``data``) may be given as bytes: it is base64-encoded with SIMD (``pybase64``) straight into
the record, never built as a Python string or scanned by ``json.dumps``.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import threading
import time
from functools import cache
from importlib.metadata import PackageNotFoundError, version
from types import TracebackType
from typing import IO, Any, Protocol

import pybase64

from data_schemas.codec import validate
from data_schemas.errors import DiskFullError, LogError, SchemaError, recover_hint
from data_schemas.mcap.chunks import Bytes, McapChunkWriter
from data_schemas.outputs import hold_writer_lock
from data_schemas.registry import (
    IMAGE_SCHEMAS,
    MESSAGE_ENCODING,
    SCHEMA_ENCODING,
    SESSION_METADATA_NAME,
    schema_dict,
    schema_json,
    topic,
)
from data_schemas.session import session_from_doc
from data_schemas.stamps import ns_from_stamp

#: errno values that mean "no room left for this file".
_FULL_ERRNOS = frozenset({errno.ENOSPC, errno.EFBIG, errno.EDQUOT})


class MonotonicClock(Protocol):
    """What the writer needs of a clock (``recorder.clock.Clock`` is one)."""

    def monotonic_ns(self) -> int:
        """Time for ``log_time``, integer ns."""
        ...


class SettableClock:
    """A clock that reads whatever time it was last set to: messages written at given log times
    (a derived log, a part of a log)."""

    def __init__(self) -> None:
        self.t_ns = 0

    def monotonic_ns(self) -> int:
        return self.t_ns

    def wall_ns(self) -> int:
        return self.t_ns

    def sleep(self, seconds: float) -> None:
        """Nothing waits: the time is set, not lived."""


def software_version() -> str:
    """Installed version of the ``bearing-slam`` distribution (``0+unknown`` from a checkout)."""
    try:
        return version("bearing-slam")
    except PackageNotFoundError:
        return "0+unknown"


class LogWriter:
    """Write a bearing-slam MCAP log: session metadata first, validated JSON messages after.

    Parameters
    ----------
    output : str, os.PathLike or binary stream
        Where to write. A path is opened (and closed) by the writer; a stream is left open.
    session_doc : dict
        The session document (``bslam.Session``); validated before anything is written.
    clock : MonotonicClock
        Time source; ``log_time`` of each message is ``clock.monotonic_ns()`` when written
        (use :class:`recorder.timebase.EpochClock` so that it reads as a date).
    chunk_bytes : int
        Close a chunk once it holds this many bytes of records.
    chunk_seconds : float
        Close a chunk once its oldest message is this old (real seconds); at most 1.
    fsync : bool
        ``os.fsync`` every closed chunk (in the background thread; ignored for streams without a
        file number).
    compression : {"", "zstd"}
        Chunk compression (see :class:`data_schemas.mcap.chunks.McapChunkWriter`): stored
        chunks are read in place; zstd saves space on raw ``bgr8`` frames, at a CPU cost.

    Examples
    --------
    >>> with LogWriter("run.mcap", doc, clock=EpochClock(SystemClock())) as log:  # doctest: +SKIP
    ...     log.write("/log", message)
    """

    def __init__(
        self,
        output: str | os.PathLike[str] | IO[bytes],
        session_doc: dict[str, Any],
        *,
        clock: MonotonicClock,
        chunk_bytes: int = 4 * 1024 * 1024,
        chunk_seconds: float = 0.5,
        fsync: bool = True,
        compression: str = "",
    ) -> None:
        if not 0 < chunk_seconds <= 1.0:
            raise ValueError(f"chunk_seconds must be in (0, 1], got {chunk_seconds}")
        session_from_doc(session_doc)
        self._clock = clock
        self._chunk_bytes = chunk_bytes
        self._chunk_seconds = chunk_seconds
        self._path: str | None = None
        if isinstance(output, str | os.PathLike):
            self._path = os.fspath(output)
            try:
                self._stream: IO[bytes] = open(self._path, "wb")  # noqa: SIM115 (closed in finish)
            except OSError as exc:
                raise LogError(f"cannot create log {self._path}: {exc.strerror}") from None
            hold_writer_lock(self._stream.fileno())  # `bslam info`: "being recorded"
            self.name = self._path
        else:
            self._stream = output
            self.name = str(getattr(output, "name", "<stream>"))
        self._fileno = _fileno(self._stream) if fsync else None
        self._mcap = McapChunkWriter(
            self._stream, library=f"bearing-slam/{software_version()}", compression=compression
        )
        self._lock = threading.Lock()
        self._channels: dict[str, tuple[int, str]] = {}
        self._schema_ids: dict[str, int] = {}
        self._sequence: dict[int, int] = {}
        self._pending_since: float | None = None
        self._messages = 0
        self._committed_messages = 0
        self._good_offset = 0
        self._error: BaseException | None = None
        self._error_raised = False
        self._finished = False
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._unsynced = False
        with self._lock:
            self._guard(self._start, session_doc)
        self._flusher = threading.Thread(target=self._flush_loop, name="mcap-flush", daemon=True)
        self._flusher.start()

    # ------------------------------------------------------------------ public API
    @property
    def message_count(self) -> int:
        """Messages accepted so far."""
        return self._messages

    @property
    def committed_count(self) -> int:
        """Messages in complete chunks already handed to the operating system."""
        return self._committed_messages

    @property
    def failed(self) -> bool:
        """True once a write error (e.g. disk full) stopped the writer."""
        return self._error is not None

    def write(self, topic_name: str, msg: dict[str, Any], *, schema: str | None = None) -> int:
        """Validate and write one message; return its ``log_time`` (ns).

        Parameters
        ----------
        topic_name : str
            A registered topic (``data_schemas.registry.TOPICS``).
        msg : dict
            The message; its ``timestamp`` (if any) becomes the MCAP ``publish_time``. A
            top-level field with ``contentEncoding: base64`` in the schema (image ``data``)
            may be bytes-like instead of a base64 string: the writer encodes it.
        schema : str, optional
            Schema name; default the topic's. An image topic may use any of
            ``IMAGE_SCHEMAS`` (e.g. ``foxglove.RawImage``), but one schema per topic per log.

        Raises
        ------
        SchemaError
            The message does not match its schema, or the topic changed schema.
        DiskFullError
            No room left; the file keeps every complete chunk.
        """
        schema_name = self._schema_for(topic_name, schema)
        data = _json_parts(schema_name, msg, what=topic_name)
        stamp = msg.get("timestamp")
        with self._lock:
            self._check_usable()
            channel_id = self._channel(topic_name, schema_name)
            log_time = self._clock.monotonic_ns()
            publish_time = ns_from_stamp(stamp) if stamp is not None else log_time
            seq = self._sequence[channel_id] = self._sequence[channel_id] + 1
            self._mcap.add_message(channel_id, seq, log_time, publish_time, data)
            self._messages += 1
            now = time.monotonic()
            if self._pending_since is None:
                self._pending_since = now
            full = (
                self._mcap.pending_bytes >= self._chunk_bytes
                or now - self._pending_since >= self._chunk_seconds
            )
            if full:
                self._commit()
        if full:
            self._wake.set()  # the background thread fsyncs the chunk
        return log_time

    def flush(self) -> None:
        """Close the open chunk and hand everything to the operating system now."""
        with self._lock:
            self._check_usable()
            self._commit()
        self._sync()

    def finish(self) -> None:
        """Write summary and footer (an indexed file) and close; safe to call twice.

        After a disk-full error this only closes the file (it stays unfinished, readable up to
        the last complete chunk) and raises the error if it was not raised before.
        """
        if self._finished:
            return
        self._finished = True
        self._stop.set()
        self._wake.set()
        self._flusher.join()
        with self._lock:
            if self._error is None:
                self._guard(self._mcap.finish)
            if self._error is None:
                self._guard(self._stream.flush)
        if self._error is None:
            self._sync()
            if self._path is not None:
                self._stream.close()
            return
        if not self._error_raised:
            self._error_raised = True
            raise self._error

    def __enter__(self) -> LogWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.finish()

    # ------------------------------------------------------------------ internals
    def _start(self, session_doc: dict[str, Any]) -> None:
        session_json = json.dumps(session_doc, separators=(",", ":"))
        self._mcap.start({SESSION_METADATA_NAME: {"json": session_json}})
        self._stream.flush()
        self._good_offset = self._stream.tell()

    def _schema_for(self, topic_name: str, schema: str | None) -> str:
        registered = topic(topic_name).schema
        if schema is None or schema == registered:
            return registered
        if registered in IMAGE_SCHEMAS and schema in IMAGE_SCHEMAS:
            return schema
        raise SchemaError(f"{topic_name}: schema {schema!r} is not allowed (expected {registered})")

    def _channel(self, topic_name: str, schema_name: str) -> int:
        known = self._channels.get(topic_name)
        if known is not None:
            if known[1] != schema_name:
                raise SchemaError(
                    f"{topic_name}: this log already writes it as {known[1]}, not {schema_name}"
                )
            return known[0]
        schema_id = self._schema_ids.get(schema_name)
        if schema_id is None:
            schema_id = self._mcap.add_schema(
                schema_name, SCHEMA_ENCODING, schema_json(schema_name)
            )
            self._schema_ids[schema_name] = schema_id
        channel_id = self._mcap.add_channel(topic_name, MESSAGE_ENCODING, schema_id)
        self._channels[topic_name] = (channel_id, schema_name)
        self._sequence[channel_id] = 0
        return channel_id

    def _commit(self) -> None:
        """Close the open chunk and flush (caller holds the lock)."""
        if self._pending_since is None:
            return
        self._guard(self._mcap.close_chunk)
        self._good_offset = self._stream.tell()
        self._committed_messages = self._messages
        self._pending_since = None
        self._unsynced = True

    def _sync(self) -> None:
        if self._fileno is None or self._error is not None:
            return
        try:
            os.fsync(self._fileno)
        except OSError as exc:
            with self._lock:
                if self._error is None:  # else the file was closed after another error
                    self._fail(exc)

    def _flush_loop(self) -> None:
        """Background thread: fsync closed chunks; close chunks that got old meanwhile."""
        period = self._chunk_seconds / 4
        while not self._stop.is_set():
            self._wake.wait(period)
            self._wake.clear()
            try:
                with self._lock:
                    since = self._pending_since
                    old = since is not None and time.monotonic() - since >= self._chunk_seconds
                    if old and self._error is None:
                        self._commit()
                    unsynced, self._unsynced = self._unsynced, False
                if unsynced:
                    self._sync()
            except LogError:
                self._error_raised = False  # nobody has seen it: the next write/finish raises
                return

    def _check_usable(self) -> None:
        if self._error is not None:
            self._error_raised = True
            raise self._error from None
        if self._finished:
            raise LogError(f"log {self.name} is already finished")

    def _guard(self, fn: Any, *args: Any) -> None:
        """Run a write operation; turn OSError into a LogError (caller holds the lock)."""
        try:
            fn(*args)
        except OSError as exc:
            self._fail(exc)

    def _fail(self, exc: OSError) -> None:
        """Stop writing after an OS error, keep the complete chunks, raise a clear error."""
        if exc.errno in _FULL_ERRNOS:
            error: LogError = DiskFullError(
                f"disk full while writing {self.name} ({exc.strerror}): "
                f"{self._committed_messages} messages kept up to the last complete chunk; "
                f"free space, then {recover_hint(self.name)}"
            )
        else:
            error = LogError(f"cannot write log {self.name}: {exc.strerror or exc}")
        self._error = error
        self._error_raised = True
        self._stop.set()
        self._abandon()
        raise error from None

    def _abandon(self) -> None:
        """Close the file we own and cut it back to the last complete chunk."""
        if self._path is None:
            return
        # the unwritten buffer is lost by design (cut off below); if truncating fails, the
        # reader skips the partial chunk at the end anyway
        with contextlib.suppress(OSError):
            self._stream.close()
        with contextlib.suppress(OSError):
            os.truncate(self._path, self._good_offset)


@cache
def _base64_fields(schema_name: str) -> frozenset[str]:
    """Top-level fields of ``schema_name`` declared ``contentEncoding: base64``."""
    properties = schema_dict(schema_name).get("properties", {})
    return frozenset(k for k, v in properties.items() if v.get("contentEncoding") == "base64")


def _json_parts(schema_name: str, msg: dict[str, Any], *, what: str) -> list[Bytes]:
    """Validate ``msg`` and return its compact JSON as byte parts (see :meth:`LogWriter.write`).

    Bytes-like values of base64 fields are validated as strings, then base64-encoded into
    their own part; they come last in the JSON object.
    """
    blobs = {k: v for k, v in msg.items() if isinstance(v, bytes | bytearray | memoryview)}
    if not blobs:
        validate(schema_name, msg, what=what)
        return [json.dumps(msg, separators=(",", ":")).encode()]
    allowed = _base64_fields(schema_name)
    for key in blobs:
        if key not in allowed:
            raise SchemaError(f"{what}: field {key!r}: bytes given, but it is not a base64 field")
    rest = {k: v for k, v in msg.items() if k not in blobs}
    validate(schema_name, {**rest, **dict.fromkeys(blobs, "")}, what=what)
    parts: list[Bytes] = [json.dumps(rest, separators=(",", ":")).encode()[:-1]]
    sep = b"," if rest else b""
    for key, value in blobs.items():
        parts += [sep + json.dumps(key).encode() + b':"', pybase64.b64encode(value), b'"']
        sep = b","
    parts.append(b"}")
    return parts


def _fileno(stream: IO[bytes]) -> int | None:
    try:
        return stream.fileno()
    except (AttributeError, OSError, ValueError):
        return None
