"""Never destroy data: check an output path before anything is written, then write it whole.

Every command that writes files makes one :class:`OutputGuard` with its inputs, claims each
output (:meth:`OutputGuard.claim`) before doing any work, and writes through
:meth:`OutputGuard.writing` (a stream) or :meth:`OutputGuard.staged` (a path for libraries that
open files themselves). A claim is refused with one line (:class:`OutputError`) when the output

* is one of the inputs, or a symbolic or hard link to one (same device and inode);
* exists (a symbolic link counts, even one that points nowhere) and ``force`` was not given,
  or is neither a regular file nor a link (``/dev/null``, a folder);
* was already claimed by the same command (two inputs mapping to one output name);
* cannot be created: missing or unwritable folder, name too long.

Outputs are written to a hidden temporary file in the destination folder
(``.NAME.XXXXXXXX.partSUFFIX``, permissions from the umask), flushed and ``fsync``-ed, and only
then published under the final name; an interrupted command leaves the old file (or no file)
whole, never a half. Publishing is exclusive: without ``force`` the temporary file is
hard-linked to the final name, which fails if another process took the name meanwhile (two
commands racing for one output: the later one refuses with one line, the first one's file
stays); with ``force`` it is renamed over the old file. A symbolic link at the final name is
replaced by the file, never written through: its target is left alone.

While a temporary file is being written its writer holds a shared ``flock`` on it; temporary
files of the same output that nobody holds (a writer killed with SIGKILL) are removed when the
output is next staged. The recorder cannot stage (its log must be on disk as it grows):
:func:`move_aside` renames an old log out of the way, :func:`create_new` claims the new name
with ``O_EXCL`` and holds a shared lock on it while the log is written, and
:func:`being_written` tells whether anyone holds such a lock (``bslam info``).
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import stat
import tempfile
import threading
import time
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import IO

from data_schemas.errors import DiskFullError, OutputError

PathLike = str | os.PathLike[str]


def _identity(path: Path) -> tuple[int, int] | None:
    try:
        st = path.stat()
    except OSError:
        return None
    return st.st_dev, st.st_ino


class OutputGuard:
    """The outputs of one command, checked against its inputs and each other.

    Parameters
    ----------
    inputs : iterable of path
        Files the command reads (never written to).
    force : bool
        Replace existing outputs (``--force``).
    """

    def __init__(self, inputs: Iterable[PathLike] = (), *, force: bool = False) -> None:
        self.force = force
        self._inputs = [Path(p) for p in inputs]
        self._claimed: dict[Path, Path] = {}

    def add_input(self, path: PathLike) -> None:
        """One more file the command reads."""
        self._inputs.append(Path(path))

    def claim(self, path: PathLike, *, what: str = "output") -> Path:
        """Check that ``path`` may be written (see module docstring); return it as a Path.

        Raises
        ------
        OutputError
            One line saying why not and what to do.
        """
        out = Path(path)
        real = Path(os.path.realpath(out))
        ident = _identity(out)
        for source in self._inputs:
            same_file = ident is not None and ident == _identity(source)
            if real == Path(os.path.realpath(source)) or same_file:
                raise OutputError(
                    f"{what} {out} is the input {source} (or a link to it): "
                    "choose another output path"
                )
        if real in self._claimed:
            raise OutputError(
                f"{what} {out} would be written twice (also for {self._claimed[real]}): "
                "give outputs distinct names"
            )
        try:
            st = out.lstat()
        except FileNotFoundError:
            st = None
        except OSError as exc:
            raise OutputError(f"cannot write {what} {out}: {exc.strerror}") from None
        if st is not None:
            if not (stat.S_ISREG(st.st_mode) or stat.S_ISLNK(st.st_mode)):
                raise OutputError(f"{what} {out} exists and is not a regular file")
            if not self.force:
                link = " (a symbolic link)" if stat.S_ISLNK(st.st_mode) else ""
                raise OutputError(f"{what} {out} exists{link}: pass --force to replace it")
        _check_folder(out, what)
        self._claimed[real] = out
        return out

    @contextlib.contextmanager
    def staged(self, path: PathLike) -> Iterator[Path]:
        """A temporary path beside ``path``, published as ``path`` when the block ends without
        error (after an ``fsync``; see the module docstring).

        On error (or interruption) the temporary file is removed and ``path`` is untouched.

        Raises
        ------
        OutputError
            The temporary file cannot be made, written or synced, or ``path`` was taken by
            another process meanwhile (without ``force``).
        """
        out = Path(path)
        folder = _folder(out)
        prefix, suffix = f".{out.name[:100]}.", f".part{out.suffix[:20]}"
        _remove_stale(folder, prefix, suffix)
        try:
            fd, tmp = tempfile.mkstemp(prefix=prefix, suffix=suffix, dir=folder)
        except OSError as exc:
            raise OutputError(f"cannot write {out}: {exc.strerror or exc}") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_SH)  # live: not stale for another process
            os.fchmod(fd, 0o666 & ~_umask())
            try:
                yield Path(tmp)
            except OSError as exc:
                if exc.errno not in _WRITE_ERRNOS:
                    raise
                raise OutputError(f"cannot write {out}: {exc.strerror}") from None
            except DiskFullError:  # a log writer's own report names the temporary file
                raise OutputError(
                    f"cannot write {out}: no room left (disk full or over the file size limit)"
                ) from None
            try:
                os.fsync(fd)
            except OSError as exc:
                raise OutputError(f"cannot write {out}: {exc.strerror or exc}") from None
            self._publish(Path(tmp), out)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            raise
        finally:
            os.close(fd)

    def _publish(self, tmp: Path, out: Path) -> None:
        """Give ``tmp`` the name ``out``: exclusive unless ``force`` (then replace)."""
        try:
            if self.force:
                os.replace(tmp, out)
                return
            try:
                os.link(tmp, out, follow_symlinks=False)
            except FileExistsError:
                raise OutputError(
                    f"{out} was created by another process meanwhile: not replaced "
                    "(pass --force to replace it)"
                ) from None
            except OSError as exc:
                if exc.errno not in _NO_LINKS:
                    raise
                if os.path.lexists(out):  # a file system without hard links: check, rename
                    raise OutputError(f"{out} was created by another process meanwhile") from None
                os.rename(tmp, out)
                return
            os.unlink(tmp)
        except OSError as exc:
            raise OutputError(f"cannot write {out}: {exc.strerror or exc}") from None

    @contextlib.contextmanager
    def writing(self, path: PathLike) -> Iterator[IO[bytes]]:
        """A binary stream whose bytes replace ``path`` only once the block ends without error."""
        with self.staged(path) as tmp, tmp.open("wb") as stream:
            yield stream
            stream.flush()

    def write_text(self, path: PathLike, text: str) -> None:
        """Write a whole text file (UTF-8) through a temporary file."""
        try:
            with self.writing(path) as stream:
                stream.write(text.encode("utf-8"))
        except OSError as exc:
            raise OutputError(f"cannot write {os.fspath(path)}: {exc.strerror or exc}") from None


#: errno values of a write that did not reach the disk: full, over a size limit, I/O error.
_WRITE_ERRNOS = frozenset({errno.ENOSPC, errno.EFBIG, errno.EDQUOT, errno.EIO})
#: errno values of link() on a file system without hard links.
_NO_LINKS = frozenset({errno.EPERM, errno.EXDEV, errno.ENOTSUP, errno.EMLINK, errno.EOPNOTSUPP})
#: A temporary file nobody holds is stale once it is this old (s): a new writer has locked its
#: own temporary file within microseconds of creating it.
_STALE_AFTER_S = 5.0


def _umask() -> int:
    """The process's umask, read without changing it (Linux), else by setting it back."""
    with contextlib.suppress(OSError, ValueError), open("/proc/self/status") as status:
        for line in status:
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _remove_stale(folder: Path, prefix: str, suffix: str) -> None:
    """Remove temporary files of one output that no writer holds (left by a killed one)."""
    try:
        names = [n for n in os.listdir(folder) if n.startswith(prefix) and n.endswith(suffix)]
    except OSError:
        return
    for name in names:
        path = folder / name
        try:
            fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
        except OSError:
            continue
        try:
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode) or time.time() - st.st_mtime < _STALE_AFTER_S:
                continue
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            os.unlink(path)
        except OSError:
            continue  # held: a live writer
        finally:
            os.close(fd)


def being_written(path: PathLike) -> bool:
    """True while a process holds the writer's lock on ``path`` (:func:`create_new`, the
    recorder's :class:`~data_schemas.mcap.writer.LogWriter`)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return True
    finally:
        os.close(fd)  # also releases the probe's lock
    return False


def hold_writer_lock(fd: int) -> None:
    """Mark the file open on ``fd`` as being written (shared lock, until ``fd`` is closed)."""
    with contextlib.suppress(OSError):  # a file system without flock: no mark, no harm
        fcntl.flock(fd, fcntl.LOCK_SH)


@contextlib.contextmanager
def create_new(path: PathLike) -> Iterator[Path]:
    """Create ``path`` as a new empty file (``O_EXCL``) and hold the writer's lock on it.

    For outputs written in place (a log being recorded): two processes given one name cannot
    both write it; the later one gets :class:`OutputError`. If the block fails before anything
    was written, the empty file is removed.
    """
    out = Path(path)
    try:
        fd = os.open(out, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o666)
    except FileExistsError:
        raise OutputError(f"{out} was created by another process meanwhile: not replaced") from None
    except OSError as exc:
        raise OutputError(f"cannot write {out}: {exc.strerror or exc}") from None
    try:
        hold_writer_lock(fd)
        yield out
    except BaseException:
        with contextlib.suppress(OSError):
            if os.fstat(fd).st_size == 0 and os.path.samestat(os.fstat(fd), out.lstat()):
                out.unlink()  # nothing was written: leave no empty file behind
        raise
    finally:
        os.close(fd)


@contextlib.contextmanager
def pipe_into(stream: IO[bytes], *, what: str) -> Iterator[str]:
    """A path a library can open and write (``/proc/self/fd/N``, a pipe) whose bytes are copied
    to ``stream``, every write checked.

    For libraries that write files themselves and only log a failed write (Rerun's file sink):
    the library never sees a full disk, and when the block ends the first write error is
    raised as :class:`OutputError` naming ``what``. The library must have closed the path by
    the end of the block (Rerun: ``disconnect``).
    """
    read_fd, write_fd = os.pipe()
    errors: list[OSError] = []

    def pump() -> None:
        with os.fdopen(read_fd, "rb", buffering=0) as source:
            while data := source.read(1 << 20):
                if errors:
                    continue  # keep draining: the writer must never block on a full pipe
                try:
                    stream.write(data)
                except OSError as exc:
                    errors.append(exc)

    thread = threading.Thread(target=pump, name="pipe-into", daemon=True)
    thread.start()
    try:
        yield f"/proc/self/fd/{write_fd}"
    finally:
        os.close(write_fd)  # with the library's own descriptor closed: end of file
        thread.join()
    if not errors:
        try:
            stream.flush()
        except OSError as exc:
            errors.append(exc)
    if errors:
        raise OutputError(f"cannot write {what}: {errors[0].strerror or errors[0]}")


def _folder(out: Path) -> Path:
    return out.parent if str(out.parent) else Path(".")


def _check_folder(out: Path, what: str) -> None:
    folder = _folder(out)
    if not folder.is_dir():
        raise OutputError(f"cannot write {what} {out}: folder {folder} does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputError(f"cannot write {what} {out}: folder {folder} is not writable")
    try:
        limit = os.pathconf(folder, "PC_NAME_MAX")
    except (OSError, ValueError):
        limit = 255
    # the temporary name adds a dot, a random part and ".part"
    if len(os.fsencode(out.name)) > limit:
        raise OutputError(f"cannot write {what}: file name too long ({len(out.name)} > {limit})")


def move_aside(path: PathLike) -> Path | None:
    """Rename an existing ``path`` to ``<stem>.old-N<suffix>`` (first free N); return it.

    None if ``path`` does not exist. For outputs that cannot be staged (a growing log). A log
    another process is writing is not moved (:class:`OutputError`).
    """
    out = Path(path)
    if not os.path.lexists(out):
        return None
    if being_written(out):
        raise OutputError(f"{out} is being written by another process: not moved")
    for n in range(1, 10_000):
        aside = out.with_name(f"{out.stem}.old-{n}{out.suffix}")
        try:
            os.link(out, aside, follow_symlinks=False)  # fails if taken: no race
        except FileExistsError:
            continue
        except OSError as exc:
            if exc.errno in (errno.EPERM, errno.EXDEV, errno.ENOTSUP, errno.EMLINK):
                if aside.exists():
                    continue
                os.rename(out, aside)
                return aside
            raise OutputError(f"cannot move {out} aside: {exc.strerror}") from None
        os.unlink(out)
        return aside
    raise OutputError(f"cannot move {out} aside: too many old copies")
