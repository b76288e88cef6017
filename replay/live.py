"""Live mode: a separate follower process shows a recording while it is being written.

``bslam record --live`` and ``bslam simulate --live`` start :class:`LiveFollower`: a child
process running ``bslam process LOG --follow`` (a compact terminal view) or ``bslam replay LOG
--follow`` (Rerun: spawn a viewer, connect to one, or save an ``.rrd``). The recorder never waits
for it and never reads from it: the child has its own session (so the terminal's Ctrl-C reaches
only the recorder, which then finishes the log, and the child ends by itself on the footer), its
output goes straight to the terminal, and the recorder only asks, between movements, whether it
is still alive (:meth:`LiveFollower.check`, a non-blocking ``waitpid``).

The child is started once the recorder has created (or truncated) the log, so it never reads an
older file of the same name.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from typing import Literal

#: How the live view is shown.
ViewKind = Literal["terminal", "spawn", "connect", "save"]


@dataclass(frozen=True)
class LiveView:
    """Where the follower shows the recording.

    Attributes
    ----------
    kind : {"terminal", "spawn", "connect", "save"}
        The terminal view of ``bslam process --follow``, or a Rerun target of ``bslam replay``.
    where : str or None
        The viewer URL (``connect``) or the ``.rrd`` path (``save``).
    idle_timeout_s : float
        The follower's ``--idle-timeout``.
    """

    kind: ViewKind = "terminal"
    where: str | None = None
    idle_timeout_s: float = 10.0

    def command(self, log: str | os.PathLike[str]) -> list[str]:
        """The follower's command line (this Python, ``-m replay.cli``)."""
        base = [sys.executable, "-m", "replay.cli"]
        follow = [os.fspath(log), "--follow", "--idle-timeout", f"{self.idle_timeout_s:g}"]
        if self.kind == "terminal":
            return [*base, "process", *follow]
        target = [f"--{self.kind}", *([self.where] if self.where is not None else [])]
        return [*base, "replay", *follow, *target]


class LiveFollower:
    """The follower process of one recording (see the module docstring).

    Parameters
    ----------
    view : LiveView
        What the follower runs.
    log : path
        The log the recorder is about to write.
    poll_s : float
        How often the watcher thread looks for the new log before starting the child.
    """

    def __init__(self, view: LiveView, log: str | os.PathLike[str], *, poll_s: float = 0.02):
        self.view = view
        self.log = os.fspath(log)
        self.process: subprocess.Popen[bytes] | None = None
        self._reported = False
        self._stop = threading.Event()
        self._before = _stamp(self.log)
        self._poll_s = poll_s
        self._watcher = threading.Thread(target=self._start_when_created, daemon=True)
        self._watcher.start()

    def check(self) -> str | None:
        """One line the first time the follower is found to have failed; else None."""
        if self._reported or self.process is None:
            return None
        code = self.process.poll()
        if code is None or code == 0:
            return None
        self._reported = True
        return f"live view stopped (follower exit {code}); the recording goes on"

    def wait(self, timeout_s: float) -> str | None:
        """After the recording: let the follower read to the footer (up to ``timeout_s``).

        Returns the failure line of :meth:`check` if it was not reported yet, or a line saying
        the follower is still running; None when it ended well.
        """
        self._stop.set()
        self._watcher.join()
        if self.process is None:
            return None
        try:
            self.process.wait(timeout_s)
        except subprocess.TimeoutExpired:
            return f"the live view is still reading {self.log} (pid {self.process.pid})"
        return self.check()

    def _start_when_created(self) -> None:
        while True:
            stamp = _stamp(self.log)
            if stamp is not None and stamp != self._before:
                break
            if self._stop.is_set():
                if stamp is None:
                    return  # the recorder never created the log
                break
            time.sleep(self._poll_s)
        self.process = subprocess.Popen(
            self.view.command(self.log),
            stdin=subprocess.DEVNULL,
            # the terminal view draws on stderr; its summary JSON on stdout is not wanted here
            stdout=subprocess.DEVNULL if self.view.kind == "terminal" else None,
            start_new_session=True,
        )


def _stamp(path: str) -> tuple[int, int] | None:
    """(inode, modification ns) of ``path``, None if it does not exist."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return None
    return st.st_ino, st.st_mtime_ns
