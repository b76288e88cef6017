"""``bslam replay --serve --host --port --web-port``: a recording reached from elsewhere.

Oracles: Rerun's own viewer binary (``rerun URL --save``) streams the served recording into a
file, read back with Rerun's reader; the web viewer answers over HTTP; Ctrl-C ends serving.
"""

from __future__ import annotations

import os
import shlex
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path
from urllib.parse import parse_qs, urlsplit

import pytest
import rerun as rr
from click.testing import CliRunner

from replay.cli import cli


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def _rerun() -> str:
    beside = Path(sys.executable).parent / "rerun"
    return str(beside) if beside.exists() else "rerun"


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore:RRD file has no footer")  # a stream saved by the viewer
def test_served_recording_reaches_a_viewer_at_the_given_host_and_ports(
    small_log: Path, tmp_path: Path
) -> None:
    grpc_port, web_port = _free_port(), _free_port()
    args = [sys.executable, "-m", "replay.cli", "replay", str(small_log), "--serve"]
    args += ["--host", "127.0.0.1", "--port", str(grpc_port), "--web-port", str(web_port)]
    server = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert server.stdout is not None
        lines = []
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            line = server.stdout.readline()
            assert line, (lines, server.stderr.read() if server.stderr else "")
            lines.append(line.strip())
            if line.startswith("serving until Ctrl-C: "):
                break
        web_url = lines[-1].removeprefix("serving until Ctrl-C: ")
        parts = urlsplit(web_url)
        assert (parts.hostname, parts.port) == ("127.0.0.1", web_port)
        grpc_url = parse_qs(parts.query)["url"][0]
        assert grpc_url == f"rerun+http://127.0.0.1:{grpc_port}/proxy"
        assert f"native viewer: rerun {grpc_url}" in lines
        with urllib.request.urlopen(web_url, timeout=10) as page:
            assert page.status == 200
            assert b"<html" in page.read().lower()

        # Rerun's viewer binary, headless, saves what the server streams
        rrd = tmp_path / "received.rrd"
        viewer = subprocess.Popen(
            [_rerun(), grpc_url, "--save", str(rrd), "--port", str(_free_port())],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        size, still = -1, 0
        while still < 3 and time.monotonic() < deadline:
            time.sleep(1.0)
            now = rrd.stat().st_size if rrd.exists() else 0
            still = still + 1 if now == size and now > 0 else 0
            size = now
        viewer.send_signal(signal.SIGINT)
        viewer.wait(timeout=20)
        entities = {chunk.entity_path for chunk in rr.chunk.RrdReader(rrd).stream()}
        assert {"/map/estimates", "/map/ellipses/L4", "/camera/panorama"} <= entities
    finally:
        server.send_signal(signal.SIGINT)
        code = server.wait(timeout=30)
    assert code == 0


def test_port_in_use_is_one_line_error(small_log: Path) -> None:
    with socket.socket() as taken:
        taken.bind(("0.0.0.0", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = CliRunner().invoke(
            cli, ["replay", str(small_log), "--serve", "--port", str(port), "--keyframes-only"]
        )
    assert result.exit_code == 1
    assert result.output.startswith(f"Error: cannot serve the recording (gRPC) on port {port} (")
    assert result.output.count("\n") == 1


def test_host_and_ports_only_with_serve(small_log: Path, tmp_path: Path) -> None:
    out = os.fspath(tmp_path / "x.rrd")
    result = CliRunner().invoke(cli, ["replay", str(small_log), "--save", out, "--port", "9000"])
    assert result.exit_code == 2
    assert "--host, --port and --web-port go with --serve" in result.output
    assert not Path(out).exists()


def test_save_says_how_to_view_without_a_display(small_log: Path, tmp_path: Path) -> None:
    rrd = tmp_path / "a run.rrd"
    result = CliRunner().invoke(cli, ["replay", str(small_log), "--save", str(rrd)])
    assert result.exit_code == 0, result.output
    (line,) = [x for x in result.output.splitlines() if x.startswith("no display here")]
    command = shlex.split(line.split("serve it to a browser: ")[1].split(", then open")[0])
    assert command == [_rerun(), "--serve-web", str(rrd)]
    assert os.access(command[0], os.X_OK) or command[0] == "rerun"
    assert "http://HOST:9090" in line
