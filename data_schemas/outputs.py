"""Never destroy data: check an output path before anything is written, then write it whole.

Every command that writes files makes one :class:`OutputGuard` with its inputs, claims each
output (:meth:`OutputGuard.claim`) before doing any work, and writes through
:meth:`OutputGuard.writing` (a stream) or :meth:`OutputGuard.staged` (a path for libraries that
open files themselves). A claim is refused with one line (:class:`OutputError`) when the output

* is one of the inputs, or a symbolic or hard link to one (same device and inode);
* exists and ``force`` was not given, or is not a regular file (``/dev/null``, a folder);
* was already claimed by the same command (two inputs mapping to one output name);
* cannot be created: missing or unwritable folder, name too long.

Outputs are written to a hidden temporary file in the destination folder and renamed into place
when complete, so an interrupted command leaves the old file (or no file) whole, never a half.
The recorder cannot do that (its log must be on disk as it grows): :func:`move_aside` renames an
old log out of the way instead of replacing it.
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import IO

from data_schemas.errors import OutputError

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
            st = out.stat()
        except FileNotFoundError:
            st = None
        except OSError as exc:
            raise OutputError(f"cannot write {what} {out}: {exc.strerror}") from None
        if st is not None:
            if not stat.S_ISREG(st.st_mode):
                raise OutputError(f"{what} {out} exists and is not a regular file")
            if not self.force:
                raise OutputError(f"{what} {out} exists: pass --force to replace it")
        _check_folder(out, what)
        self._claimed[real] = out
        return out

    @contextlib.contextmanager
    def staged(self, path: PathLike) -> Iterator[Path]:
        """A temporary path beside ``path``, renamed onto it when the block ends without error.

        On error (or interruption) the temporary file is removed and ``path`` is untouched.

        Raises
        ------
        OutputError
            The temporary file cannot be made in the folder, or cannot be renamed onto
            ``path``.
        """
        out = Path(path)
        try:
            fd, tmp = tempfile.mkstemp(
                prefix=f".{out.name[:100]}.", suffix=f".part{out.suffix[:20]}", dir=_folder(out)
            )
        except OSError as exc:
            raise OutputError(f"cannot write {out}: {exc.strerror or exc}") from None
        os.close(fd)
        try:
            yield Path(tmp)
            try:
                os.replace(tmp, out)
            except OSError as exc:
                raise OutputError(f"cannot write {out}: {exc.strerror or exc}") from None
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            raise

    @contextlib.contextmanager
    def writing(self, path: PathLike) -> Iterator[IO[bytes]]:
        """A binary stream whose bytes replace ``path`` only once the block ends without error."""
        with self.staged(path) as tmp, tmp.open("wb") as stream:
            yield stream
            stream.flush()
            os.fsync(stream.fileno())

    def write_text(self, path: PathLike, text: str) -> None:
        """Write a whole text file (UTF-8) through a temporary file."""
        try:
            with self.writing(path) as stream:
                stream.write(text.encode("utf-8"))
        except OSError as exc:
            raise OutputError(f"cannot write {os.fspath(path)}: {exc.strerror or exc}") from None


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

    None if ``path`` does not exist. For outputs that cannot be staged (a growing log).
    """
    out = Path(path)
    if not out.exists():
        return None
    for n in range(1, 10_000):
        aside = out.with_name(f"{out.stem}.old-{n}{out.suffix}")
        try:
            os.link(out, aside)  # fails if taken: no race with another writer
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
