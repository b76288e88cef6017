"""Run one function over many tasks: in process, on a local process pool, or on a Dask cluster.

The one runner of ``bslam process`` (many logs) and ``bslam experiment`` (many runs). Every
task runs guarded: an exception becomes a failed :class:`Outcome` with a one-line reason, so one
bad task never sinks the others. A tqdm bar on stderr shows progress, and ``on_outcome`` sees
each outcome as it completes (e.g. to print a line per task above the bar with
``tqdm.write``). Worker processes live for the whole map (one per worker), so modules imported
once are reused by every task; on Linux the pool forks, and whatever the caller imported before
the call is already loaded.
"""

from __future__ import annotations

import signal
import sys
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from functools import partial
from typing import Any, Generic, TypeVar

from tqdm import tqdm

from data_schemas.errors import BslamError

A = TypeVar("A")
T = TypeVar("T")


class SchedulerError(BslamError):
    """The Dask scheduler cannot be reached."""


@dataclass(frozen=True)
class Outcome(Generic[T]):
    """The result of one task: its value, or a one-line error; wall time in seconds."""

    index: int
    value: T | None
    error: str | None
    seconds: float

    @property
    def ok(self) -> bool:
        """True when the task returned a value."""
        return self.error is None


def _one_line(exc: BaseException) -> str:
    """A user error's own message; anything else prefixed with its type (first line only)."""
    text = str(exc).strip().splitlines()
    if isinstance(exc, BslamError) and text:
        return text[0]
    return f"{type(exc).__name__}: {text[0]}" if text else type(exc).__name__


def _guarded(fn: Callable[[A], T], index: int, task: A) -> Outcome[T]:
    start = time.perf_counter()
    try:
        value = fn(task)
    except Exception as exc:  # a failing task is reported, the others go on
        return Outcome(index, None, _one_line(exc), time.perf_counter() - start)
    return Outcome(index, value, None, time.perf_counter() - start)


def _collect(result: Callable[[], Outcome[T]], index: int) -> Outcome[T]:
    """The outcome of a finished future; a dead worker becomes a failed outcome."""
    try:
        return result()
    except Exception as exc:  # the worker itself died (killed, out of memory)
        return Outcome(index, None, _one_line(exc), 0.0)


def run_tasks(
    fn: Callable[[A], T],
    tasks: Sequence[A],
    *,
    workers: int = 1,
    scheduler: str | None = None,
    desc: str = "runs",
    unit: str = "run",
    progress: bool = True,
    on_outcome: Callable[[Outcome[T]], None] | None = None,
    connect_timeout: str = "10s",
) -> list[Outcome[T]]:
    """Apply ``fn`` to every task and return the outcomes in task order.

    Parameters
    ----------
    fn : callable
        A module-level function (it is pickled for worker processes).
    tasks : sequence
        Picklable arguments, one per call.
    workers : int
        Worker processes of the local pool; 1 runs in this process (no pool).
    scheduler : str, optional
        Address of a Dask scheduler (``tcp://host:8786``); when given, ``workers`` is ignored
        and the cluster's workers run the tasks.
    desc, unit : str
        Label and unit of the progress bar.
    progress : bool
        Show the progress bar on stderr.
    on_outcome : callable, optional
        Called in this process with each outcome as soon as its task finishes.
    connect_timeout : str
        How long to try reaching the Dask scheduler (Dask duration, e.g. ``"10s"``).

    Returns
    -------
    list of Outcome
        One per task, in the order of ``tasks``.

    Raises
    ------
    SchedulerError
        ``scheduler`` cannot be reached.
    """
    if scheduler is not None:
        from replay.extras import require

        require("distributed", extra="experiments", feature="a Dask scheduler (--scheduler)")
    guarded = partial(_guarded, fn)
    outcomes: list[Outcome[T]] = []
    # a bar only on a terminal (tqdm's disable=None), and only if asked
    bar = tqdm(
        total=len(tasks), desc=desc, unit=unit, file=sys.stderr, disable=None if progress else True
    )

    def done(outcome: Outcome[T]) -> None:
        outcomes.append(outcome)
        bar.update()
        if on_outcome is not None:
            on_outcome(outcome)

    with bar:
        if scheduler is not None:
            _run_dask(guarded, tasks, scheduler, connect_timeout, done)
        elif workers <= 1 or len(tasks) <= 1:
            for i, task in enumerate(tasks):
                done(guarded(i, task))
        else:
            pool = ProcessPoolExecutor(
                max_workers=min(workers, len(tasks)), initializer=_ignore_sigint
            )
            try:
                futures: dict[Future[Outcome[T]], int] = {
                    pool.submit(guarded, i, task): i for i, task in enumerate(tasks)
                }
                for fut in as_completed(futures):
                    done(_collect(fut.result, futures[fut]))
            except BaseException:  # Ctrl-C, SIGTERM (as SystemExit), a bug: no orphan workers
                _kill_workers(pool)
                raise
            pool.shutdown()
    return sorted(outcomes, key=lambda o: o.index)


def _ignore_sigint() -> None:
    """Pool worker initializer: Ctrl-C reaches the whole process group; the parent handles it
    (and then kills the workers), so a worker does not print a traceback of its own."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _kill_workers(pool: ProcessPoolExecutor) -> None:
    """Stop a pool at once: cancel queued tasks and kill its worker processes."""
    processes = list((getattr(pool, "_processes", None) or {}).values())
    for process in processes:
        process.kill()
    for process in processes:
        process.join(timeout=1.0)
    # the pool sees its workers gone (as after a crash) and fails what was left; wait for that
    pool.shutdown(wait=True, cancel_futures=True)


def _run_dask(
    guarded: Callable[[int, A], Outcome[T]],
    tasks: Sequence[A],
    scheduler: str,
    connect_timeout: str,
    done: Callable[[Outcome[T]], Any],
) -> None:
    from distributed import Client
    from distributed import as_completed as dask_as_completed

    try:
        client = Client(scheduler, timeout=connect_timeout)  # type: ignore[no-untyped-call]
    except (OSError, TimeoutError, ValueError) as exc:
        raise SchedulerError(f"cannot reach the Dask scheduler at {scheduler} ({exc})") from None
    with client:
        futures = client.map(guarded, list(range(len(tasks))), list(tasks), pure=False)
        index = {fut.key: i for i, fut in enumerate(futures)}
        for fut in dask_as_completed(futures):  # type: ignore[no-untyped-call]
            done(_collect(fut.result, index[fut.key]))
