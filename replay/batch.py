"""Many logs at once: expand folders and globs, spread the logs over processes or a Dask cluster.

One log that fails (not MCAP, unfinished, ...) is reported as a failed :class:`LogOutcome` and
does not stop the others. The same picklable job function runs in-process, in a local process
pool (``workers > 1``) or on a Dask cluster (``scheduler`` address).
"""

from __future__ import annotations

import glob
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

from data_schemas.errors import BslamError, LogError
from replay.records import MethodConfig

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


@dataclass(frozen=True)
class LogOutcome:
    """What processing one log gave: a one-line result or a one-line error."""

    log: Path
    ok: bool
    message: str
    summary: dict[str, object] | None = None


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
    logs: Sequence[Path], out: Path | None, summary: Path | None, method: MethodConfig
) -> list[LogJob]:
    """One job per log. One log: ``out``/``summary`` are files; many: folders (created)."""
    if len(logs) == 1:
        return [LogJob(logs[0], out, summary, method)]
    for folder in (out, summary):
        if folder is not None:
            if folder.exists() and not folder.is_dir():
                raise NoLogsError(f"{folder}: with many logs, --out and --summary are folders")
            folder.mkdir(parents=True, exist_ok=True)
    return [
        LogJob(
            log,
            None if out is None else out / (log.stem + DERIVED_SUFFIX),
            None if summary is None else summary / (log.stem + SUMMARY_SUFFIX),
            method,
        )
        for log in logs
    ]


def run_job(job: LogJob) -> LogOutcome:
    """Process one log; a user error becomes a failed outcome (picklable, for pools)."""
    from replay.process import process_log, result_line

    try:
        doc = process_log(job.log, job.method, out=job.out, summary=job.summary)
    except BslamError as exc:
        return LogOutcome(job.log, False, str(exc))
    return LogOutcome(job.log, True, result_line(doc), doc)


def run_jobs(
    jobs: Sequence[LogJob],
    *,
    workers: int = 1,
    scheduler: str | None = None,
    job_fn: Callable[[LogJob], LogOutcome] = run_job,
    connect_timeout: str = "10s",
) -> Iterator[LogOutcome]:
    """Run jobs and yield outcomes as they complete.

    Parameters
    ----------
    jobs : sequence of LogJob
    workers : int
        Local processes; 1 runs in this process.
    scheduler : str, optional
        Address of a Dask scheduler (``tcp://host:8786``); overrides ``workers``.
    job_fn : callable
        The per-log function (a module-level function, so that it pickles).
    connect_timeout : str
        How long to try reaching the Dask scheduler (Dask duration, e.g. ``"10s"``).
    """
    if scheduler is not None:
        yield from _run_dask(jobs, scheduler, job_fn, connect_timeout)
    elif workers <= 1 or len(jobs) == 1:
        for job in jobs:
            yield job_fn(job)
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            futures = [pool.submit(job_fn, job) for job in jobs]
            for future in as_completed(futures):
                yield future.result()


class SchedulerError(BslamError):
    """The Dask scheduler cannot be reached."""


def _run_dask(
    jobs: Sequence[LogJob],
    scheduler: str,
    job_fn: Callable[[LogJob], LogOutcome],
    connect_timeout: str,
) -> Iterator[LogOutcome]:
    from distributed import Client
    from distributed import as_completed as dask_as_completed

    try:
        client = Client(scheduler, timeout=connect_timeout)  # type: ignore[no-untyped-call]
    except (OSError, TimeoutError) as exc:
        raise SchedulerError(f"cannot reach the Dask scheduler at {scheduler} ({exc})") from None
    with client:
        futures = client.map(job_fn, list(jobs), pure=False)
        for future in dask_as_completed(futures):  # type: ignore[no-untyped-call]
            outcome: LogOutcome = future.result()
            yield outcome
