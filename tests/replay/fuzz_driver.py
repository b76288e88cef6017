"""Run one ``bslam`` command over mutated logs in one process; print one JSON line per log.

``python fuzz_driver.py COMMAND OUT_FOLDER LOG...``: each log runs with a 5 s alarm (a hang is
reported, not waited for); the report holds the exit code, stderr, whether a traceback was
raised, the seconds taken and what lies under the output's final name. The last line is the
driver's peak memory (MiB). Started by ``test_fuzz_logs.py`` in a process of its own.
"""

from __future__ import annotations

import json
import resource
import signal
import sys
import time
import traceback
from pathlib import Path
from types import FrameType

from click.testing import CliRunner

from replay.cli import cli

HANG_S = 5


class Hang(Exception):
    """The command took longer than HANG_S."""


def _alarm(signum: int, frame: FrameType | None) -> None:
    raise Hang


def _args(command: str, log: Path, out: Path) -> list[str]:
    if command == "recover":
        return ["recover", str(log), str(out / "fixed.mcap")]
    if command == "process":
        return ["process", str(log), "--out", str(out / "d.mcap"), "--summary", str(out / "s.json")]
    if command == "replay":
        return ["replay", str(log), "--save", str(out / "r.rrd"), "--keyframes-only"]
    return ["info", str(log)]


def main() -> None:
    command, out_root, *logs = sys.argv[1:]
    signal.signal(signal.SIGALRM, _alarm)
    runner = CliRunner()
    for log in map(Path, logs):
        out = Path(out_root) / log.stem
        out.mkdir()
        start = time.monotonic()
        signal.alarm(HANG_S)
        try:
            result = runner.invoke(cli, _args(command, log, out), catch_exceptions=True)
            signal.alarm(0)
            hang = isinstance(result.exception, Hang)
            exc = result.exception
            crash = exc is not None and not isinstance(exc, SystemExit | Hang)
            report = {
                "log": log.name,
                "code": result.exit_code,
                "stderr": result.stderr,
                "traceback": "".join(traceback.format_exception(exc)) if crash and exc else "",
                "hang": hang,
            }
        except Hang:
            report = {"log": log.name, "code": None, "stderr": "", "traceback": "", "hang": True}
        finally:
            signal.alarm(0)
        report["seconds"] = time.monotonic() - start
        report["peak_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024
        report["outputs"] = sorted(p.name for p in out.iterdir())
        print(json.dumps(report), flush=True)
    print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024, flush=True)


if __name__ == "__main__":
    main()
