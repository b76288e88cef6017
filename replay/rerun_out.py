"""``bslam replay`` as a library call: one log through the stages into a Rerun recording."""

from __future__ import annotations

import contextlib
import os
import socket
import sys
from dataclasses import dataclass
from typing import IO, Any, Literal
from urllib.parse import quote, urlsplit

import rerun as rr

from data_schemas.errors import BslamError
from data_schemas.mcap.follow import FollowedLog
from data_schemas.mcap.open import LogSource, MessageLog, entered, log_path
from data_schemas.outputs import OutputGuard, create_new, pipe_into
from replay.blueprint import method_blueprint
from replay.process import process_log
from replay.records import PRIORS, MethodConfig, Sink
from replay.sinks.rerun_sink import RerunSink
from replay.sinks.summary import RunSummary

APPLICATION_ID = "bearing-slam"


class ViewerError(BslamError):
    """The Rerun viewer or server could not be started or reached."""


@dataclass(frozen=True)
class RerunTarget:
    """Where the recording goes: a file, a spawned viewer, a running viewer, or a server."""

    kind: Literal["save", "spawn", "connect", "serve"]
    where: str | None = None
    port: int | None = None
    """``serve``: the gRPC port (Rerun's default 9876 if None)."""


#: Rerun's default ports: its gRPC server and its web viewer.
DEFAULT_GRPC_PORT = 9876
DEFAULT_WEB_PORT = 9090


@dataclass(frozen=True)
class ServeAddress:
    """Where ``--serve`` is reached from other machines.

    Rerun 0.41's servers listen on every interface (its Python API takes no bind address);
    ``host`` is the name or address a viewer elsewhere uses for this machine.
    """

    host: str
    grpc_port: int = DEFAULT_GRPC_PORT
    web_port: int = DEFAULT_WEB_PORT

    @property
    def grpc_url(self) -> str:
        """What a native viewer opens: ``rerun rerun+http://HOST:PORT/proxy``."""
        return f"rerun+http://{self.host}:{self.grpc_port}/proxy"

    @property
    def web_url(self) -> str:
        """The web viewer, told where the recording is served (open it in a browser)."""
        return f"http://{self.host}:{self.web_port}/?url={quote(self.grpc_url, safe='')}"


def check_port_free(port: int, what: str) -> None:
    """Refuse a port something already listens on (Rerun would fail only in the background).

    Raises
    ------
    ViewerError
        ``port`` is taken (or may not be bound here).
    """
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        try:
            probe.bind(("0.0.0.0", port))
        except OSError as exc:
            raise ViewerError(
                f"cannot serve the {what} on port {port} ({exc.strerror or exc}); "
                "choose another port"
            ) from None


def serve_web_viewer(address: ServeAddress) -> None:
    """Host Rerun's web viewer on ``address.web_port``, connecting to ``address.grpc_url``."""
    check_port_free(address.web_port, "web viewer")
    try:
        rr.serve_web_viewer(
            web_port=address.web_port, open_browser=False, connect_to=address.grpc_url
        )
    except RuntimeError as exc:
        raise ViewerError(f"cannot serve the web viewer: {exc}") from None


def open_recording(
    name: str, target: RerunTarget, *, live: bool = False
) -> tuple[rr.RecordingStream, str | None]:
    """A recording stream connected to ``target``; also the server URL when serving.

    ``live``: the blueprint follows the latest movement (a log being followed).
    """
    if target.kind == "spawn":
        _check_display()
    elif target.kind == "connect":
        _check_reachable(target.where or DEFAULT_CONNECT_URL)
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
            port = DEFAULT_GRPC_PORT if target.port is None else target.port
            check_port_free(port, "recording (gRPC)")
            url = rec.serve_grpc(grpc_port=port, default_blueprint=blueprint)
    except (RuntimeError, OSError) as exc:
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ViewerError(f"cannot open the Rerun {target.kind} target: {reason}") from None
    return rec, url


def recording_id(log: MessageLog) -> str:
    """The Rerun recording id of a log: its session id, so two logs never merge in a viewer."""
    return log.session.session_id


#: Where ``connect_grpc`` streams when given no URL (the viewer's default).
DEFAULT_CONNECT_URL = "rerun+http://127.0.0.1:9876/proxy"


def _check_display() -> None:
    """A spawned viewer needs a display; without one it dies and nothing is shown."""
    if sys.platform.startswith("linux") and not (
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    ):
        raise ViewerError(
            "--spawn needs a display (neither DISPLAY nor WAYLAND_DISPLAY is set); "
            "use --save FILE.rrd and open it where there is one, or --serve"
        )


def _check_reachable(url: str, timeout_s: float = 2.0) -> None:
    """Rerun connects in the background and only logs a failure: try the address first."""
    parsed = urlsplit(url.removeprefix("rerun+"))
    host, port = parsed.hostname, parsed.port
    if host is None or port is None:
        raise ViewerError(f"--connect {url}: expected a URL like {DEFAULT_CONNECT_URL}")
    try:
        socket.create_connection((host, port), timeout=timeout_s).close()
    except OSError as exc:
        raise ViewerError(
            f"no Rerun viewer at {url} ({exc.strerror or exc}); start one with `rerun`, "
            "or use --save FILE.rrd"
        ) from None


def replay_log(
    log: LogSource,
    method: MethodConfig,
    rec: rr.RecordingStream,
    *,
    images: bool = True,
    live: bool = False,
    out: str | os.PathLike[str] | None = None,
    summary: str | os.PathLike[str] | None = None,
    force: bool = False,
    extra_sinks: tuple[Sink, ...] = (),
) -> RunSummary:
    """Stream every stage of ``log`` to ``rec`` (and Fig. 1); return its summary.

    ``out`` and ``summary``, if given, also receive the derived log and the summary JSON
    (existing ones replaced only with ``force``). ``live``: frames are sent with each movement
    (a log being followed), not in batches. ``extra_sinks`` are fed by the same pass (a
    progress bar).
    """
    sink = RerunSink(rec, images=images, live=live)
    return process_log(
        log, method, out=out, summary=summary, extra_sinks=(sink, *extra_sinks), force=force
    )


def save_rrd(
    log: LogSource,
    method: MethodConfig,
    rrd: str | os.PathLike[str],
    *,
    force: bool = False,
    skip_corrupt: bool = False,
    **kw: Any,
) -> RunSummary:
    """Replay ``log`` (a path, or a log already opened or followed) into the file ``rrd``.

        A finished log is replayed into a file beside ``rrd`` that is renamed into place on return.
        A log being followed (:class:`data_schemas.mcap.follow.FollowedLog`) is written to ``rrd``
    directly,
        so that what was read is kept however the log ends.

        Raises
        ------
        OutputError
            ``rrd`` is the log (or a link to it), or exists without ``force``.
    """
    guard = OutputGuard([log_path(log)], force=force)
    guard.claim(rrd, what="Rerun recording")
    followed = isinstance(log, FollowedLog)
    with contextlib.ExitStack() as stack:
        opened = entered(log, stack, skip_corrupt=skip_corrupt)  # a bad log fails here, first
        # Rerun only logs a failed write: it writes into a pipe, and every write to the file
        # is ours (checked, then fsynced before the file is renamed into place)
        stream: IO[bytes]
        if followed:  # written in place, so that what was read is kept however the log ends
            if force and os.path.lexists(rrd):
                os.unlink(rrd)  # the old recording (or the link itself, never its target)
            stack.enter_context(create_new(rrd))  # a second writer of the name refuses
            stream = stack.enter_context(open(rrd, "wb"))
        else:
            stream = stack.enter_context(guard.writing(rrd))
        pipe = stack.enter_context(pipe_into(stream, what=f"Rerun recording {os.fspath(rrd)}"))
        rec, _ = open_recording(recording_id(opened), RerunTarget("save", pipe), live=followed)
        try:
            return replay_log(opened, method, rec, force=force, live=followed, **kw)
        finally:
            rec.disconnect()
