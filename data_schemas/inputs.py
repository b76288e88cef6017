"""Open the files a command reads: regular files only, and text files of bounded size.

A FIFO, a device (``/dev/zero``) or a folder given as an input would make a reader wait for a
writer that never comes or read without end. :func:`open_input` opens without waiting
(``O_NONBLOCK``) and refuses anything but a regular file with one line; :func:`read_text` reads
a small document (scenario, calibration) and refuses one over its size limit. A log still
being written is read by ``--follow`` (:mod:`data_schemas.mcap.follow`), which takes a FIFO
too and gives up on it after its idle timeout.
"""

from __future__ import annotations

import fcntl
import os
import stat
from typing import BinaryIO

from data_schemas.errors import BslamError

#: The largest JSON document read from a file (scenario, calibration): bytes.
MAX_DOCUMENT_BYTES = 16 * 1024 * 1024


def file_kind(mode: int) -> str:
    """What ``mode`` (``st_mode``) is, for a message: "a FIFO", "a folder", ..."""
    kinds = (
        (stat.S_ISFIFO, "a FIFO"),
        (stat.S_ISDIR, "a folder"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
    )
    return next((name for test, name in kinds if test(mode)), "not a regular file")


def open_fd(
    path: str | os.PathLike[str], *, what: str, error: type[BslamError], fifo: bool = False
) -> int:
    """A read-only descriptor of ``path``, a regular file (or, if ``fifo``, a FIFO that does
    not block).

    Raises ``error`` with one line if it cannot be opened or is something else, except
    FileNotFoundError for a ``fifo`` caller (``--follow`` waits for the log to appear).
    """
    name = os.fspath(path)
    try:
        fd = os.open(name, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except FileNotFoundError:
        if fifo:
            raise
        raise error(f"cannot open {what} {name}: no such file") from None
    except OSError as exc:
        raise error(f"cannot open {what} {name}: {exc.strerror or exc}") from None
    try:
        mode = os.fstat(fd).st_mode
        if not (stat.S_ISREG(mode) or (fifo and stat.S_ISFIFO(mode))):
            raise error(f"{what} {name} is {file_kind(mode)}, not a regular file: give a file")
        if not fifo:
            fcntl.fcntl(fd, fcntl.F_SETFL, fcntl.fcntl(fd, fcntl.F_GETFL) & ~os.O_NONBLOCK)
    except BaseException:
        os.close(fd)
        raise
    return fd


def open_input(path: str | os.PathLike[str], *, what: str, error: type[BslamError]) -> BinaryIO:
    """``path`` opened for reading in binary, refused with ``error`` unless a regular file."""
    return os.fdopen(open_fd(path, what=what, error=error), "rb")


def read_text(
    path: str | os.PathLike[str],
    *,
    what: str,
    error: type[BslamError],
    max_bytes: int = MAX_DOCUMENT_BYTES,
) -> str:
    """The UTF-8 text of a regular file of at most ``max_bytes`` (else ``error``, one line)."""
    with open_input(path, what=what, error=error) as file:
        try:
            data = file.read(max_bytes + 1)
        except OSError as exc:
            raise error(f"cannot read {what} {os.fspath(path)}: {exc.strerror or exc}") from None
    if len(data) > max_bytes:
        raise error(f"{what} {os.fspath(path)} is larger than {max_bytes} bytes: not a {what}")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"{what} {os.fspath(path)} is not UTF-8 text ({exc.reason})") from None
