"""``bslam replay`` as a library call: one log through the stages into a Rerun recording."""

from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import rerun as rr

from data_schemas.errors import BslamError
from data_schemas.outputs import OutputGuard
from replay.blueprint import method_blueprint
from replay.follow import FollowedLog
from replay.process import open_log, process_log
from replay.records import PRIORS, MethodConfig
from replay.sinks.rerun_sink import RerunSink
from replay.stages import MessageLog

APPLICATION_ID = "bearing-slam"


class ViewerError(BslamError):
    """The Rerun viewer or server could not be started or reached."""


@dataclass(frozen=True)
class RerunTarget:
    """Where the recording goes: a file, a spawned viewer, a running viewer, or a server."""

    kind: Literal["save", "spawn", "connect", "serve"]
    where: str | None = None


def open_recording(
    name: str, target: RerunTarget, *, live: bool = False
) -> tuple[rr.RecordingStream, str | None]:
    """A recording stream connected to ``target``; also the server URL when serving.

    ``live``: the blueprint follows the latest movement (a log being followed).
    """
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=name)
    blueprint = method_blueprint(fig1_priors=PRIORS, live=live)
    url = None
    try:
        if target.kind == "save":
            assert target.where is not None
            rec.save(target.where, default_blueprint=blueprint)
        elif target.kind == "spawn":
            rec.spawn(default_blueprint=blueprint)
        elif target.kind == "connect":
            rec.connect_grpc(target.where, default_blueprint=blueprint)
        else:
            url = rec.serve_grpc(default_blueprint=blueprint)
    except (RuntimeError, OSError) as exc:
        raise ViewerError(f"cannot open the Rerun {target.kind} target ({exc})") from None
    return rec, url


def recording_id(log: MessageLog) -> str:
    """The Rerun recording id of a log: its session id, so two logs never merge in a viewer."""
    return log.session.session_id


def replay_log(
    log: str | os.PathLike[str] | MessageLog,
    method: MethodConfig,
    rec: rr.RecordingStream,
    *,
    images: bool = True,
    live: bool = False,
    out: str | os.PathLike[str] | None = None,
    summary: str | os.PathLike[str] | None = None,
    force: bool = False,
) -> dict[str, Any]:
    """Stream every stage of ``log`` to ``rec`` (and Fig. 1); return the summary document.

    ``out`` and ``summary``, if given, also receive the derived log and the summary JSON
    (existing ones replaced only with ``force``). ``live``: frames are sent with each movement
    (a log being followed), not in batches.
    """
    sink = RerunSink(rec, images=images, live=live)
    return process_log(log, method, out=out, summary=summary, extra_sinks=(sink,), force=force)


def save_rrd(
    log: str | os.PathLike[str] | MessageLog,
    method: MethodConfig,
    rrd: str | os.PathLike[str],
    *,
    force: bool = False,
    skip_corrupt: bool = False,
    **kw: Any,
) -> dict[str, Any]:
    """Replay ``log`` (a path, or a log already opened or followed) into the file ``rrd``.

    A finished log is replayed into a file beside ``rrd`` that is renamed into place on return.
    A log being followed (:class:`replay.follow.FollowedLog`) is written to ``rrd`` directly,
    so that what was read is kept however the log ends.

    Raises
    ------
    OutputError
        ``rrd`` is the log (or a link to it), or exists without ``force``.
    """
    source = log if isinstance(log, str | os.PathLike) else log.path
    guard = OutputGuard([source], force=force)
    guard.claim(rrd, what="Rerun recording")
    followed = isinstance(log, FollowedLog)
    with contextlib.ExitStack() as stack:
        opened = (
            stack.enter_context(open_log(log, skip_corrupt=skip_corrupt))
            if isinstance(log, str | os.PathLike)
            else log
        )  # a bad log fails here, before any output exists
        part = Path(rrd) if followed else stack.enter_context(guard.staged(rrd))
        rec, _ = open_recording(
            recording_id(opened), RerunTarget("save", os.fspath(part)), live=followed
        )
        try:
            return replay_log(opened, method, rec, force=force, live=followed, **kw)
        finally:
            rec.disconnect()
