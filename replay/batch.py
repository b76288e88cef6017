"""Many logs at once: expand folders and globs into logs, plan one job per log.

:func:`process_job` is the picklable per-log function that :func:`replay.parallel.run_tasks`
runs in process, on a local process pool or on a Dask cluster; a log that fails (not MCAP,
unfinished, ...) becomes a failed outcome there and does not stop the others.
"""

from __future__ import annotations

import glob
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from data_schemas.errors import LogError
from data_schemas.mcap.window import LogWindow
from data_schemas.outputs import OutputGuard
from replay.records import MethodConfig

if TYPE_CHECKING:
    from replay.sinks.summary import RunSummary

DERIVED_SUFFIX = ".derived.mcap"
SUMMARY_SUFFIX = ".summary.json"


class NoLogsError(LogError):
    """The command line names no existing log."""


@dataclass(frozen=True)
class LogJob:
    """One log to process and where its outputs go (None: not written)."""

    log: Path
    out: Path | None
    summary: Path | None
    method: MethodConfig
    force: bool = False
    skip_corrupt: bool = False
    window: LogWindow | None = None


def expand_logs(args: Sequence[str]) -> list[Path]:
    """Logs named by ``args``: files, folders (their ``*.mcap``) and glob patterns, in order.

    Derived logs (``*.derived.mcap``) found in folders or globs are left out.
    """
    logs: list[Path] = []
    for arg in args:
        path = Path(arg)
        if path.is_dir():
            found = sorted(path.glob("*.mcap"))
        elif any(c in arg for c in "*?["):
            found = sorted(Path(p) for p in glob.glob(arg, recursive=True))
        else:
            if not path.exists():
                raise NoLogsError(f"{arg}: no such file or folder")
            logs.append(path)
            continue
        found = [p for p in found if not p.name.endswith(DERIVED_SUFFIX)]
        if not found:
            raise NoLogsError(f"{arg}: no .mcap log found there")
        logs.extend(found)
    unique = list(dict.fromkeys(logs))
    if not unique:
        raise NoLogsError("no log given")
    return unique


def plan_jobs(
    logs: Sequence[Path],
    out: Path | None,
    summary: Path | None,
    method: MethodConfig,
    *,
    force: bool = False,
    skip_corrupt: bool = False,
    window: LogWindow | None = None,
) -> list[LogJob]:
    """One job per log. One log: ``out``/``summary`` are files; many: folders (created).

    Every output is checked before any job runs (:class:`data_schemas.outputs.OutputGuard`):
    none may be a log, exist (without ``force``), or be shared by two logs.
    """
    if len(logs) == 1:
        jobs = [LogJob(logs[0], out, summary, method, force, skip_corrupt, window)]
    else:
        for folder in (out, summary):
            if folder is not None:
                if folder.exists() and not folder.is_dir():
                    raise NoLogsError(f"{folder}: with many logs, --out and --summary are folders")
                folder.mkdir(parents=True, exist_ok=True)
        jobs = [
            LogJob(
                log,
                None if out is None else out / (log.stem + DERIVED_SUFFIX),
                None if summary is None else summary / (log.stem + SUMMARY_SUFFIX),
                method,
                force,
                skip_corrupt,
                window,
            )
            for log in logs
        ]
    guard = OutputGuard(logs, force=force)
    for job in jobs:
        for path, what in ((job.out, "derived log"), (job.summary, "summary")):
            if path is not None:
                guard.claim(path, what=f"{what} of {job.log}")
    return jobs


def process_job(job: LogJob) -> RunSummary:
    """Process one log; return its summary (a module-level function, for pools: the summary
    is plain data, pickled back from a worker process or a Dask worker)."""
    from replay.process import process_log

    return process_log(
        job.log,
        job.method,
        out=job.out,
        summary=job.summary,
        force=job.force,
        skip_corrupt=job.skip_corrupt,
        window=job.window,
    )
