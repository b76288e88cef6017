"""The ``bslam`` command line: one click group whose commands load on demand.

Each command lives in its own module and is imported only when it runs (or when ``--help``
lists it), so ``bslam --help`` stays fast and ``bslam record`` on a robot never imports scipy or
Rerun. Commands only compose library calls. Any :class:`~data_schemas.errors.BslamError` becomes
one line on stderr and exit code 1; a usage error is one line and a hint to ``--help``, exit 2
(click's convention). Ctrl-C exits 130; SIGTERM stops the command the same way (exit 143):
open files are closed, worker processes are stopped, a log being recorded is finished.
"""

from __future__ import annotations

import gc
import os
import signal
import sys
from types import FrameType


def _stop_at_once(signum: int, frame: FrameType | None) -> None:
    """A stop signal while the command starts (nothing open yet): one line, exit 128 + signum.

    Raising here instead would surface as a traceback from whatever module was importing
    ("ImportError: initialization failed" from numpy's C code, say).
    """
    os.write(2, b"interrupted\n" if signum == signal.SIGINT else b"terminated\n")
    os._exit(128 + signum)


def _started_as_bslam() -> bool:
    """This import is the ``bslam`` command starting (the console script or ``-m replay.cli``),
    not a program that imports the CLI (tests, notebooks), whose signals stay its own."""
    first = sys.argv[0] if sys.argv else ""
    return os.path.basename(first) == "bslam" or first == "-m"


if _started_as_bslam():  # before the imports below (click alone takes ~50 ms)
    for _sig in (signal.SIGINT, signal.SIGTERM):
        if signal.getsignal(_sig) in (signal.SIG_DFL, signal.default_int_handler):
            signal.signal(_sig, _stop_at_once)

import atexit  # noqa: E402
import importlib  # noqa: E402
import threading  # noqa: E402
from collections.abc import Sequence  # noqa: E402
from typing import Any  # noqa: E402

import click  # noqa: E402

from data_schemas.errors import BslamError  # noqa: E402

#: The stop signal received while a command runs (None: none yet).
_stop_signal: list[int] = []

#: command name -> "module:attribute". Add a command by adding a line here.
COMMANDS: dict[str, str] = {
    "info": "replay.cli.info:info",
    "import": "replay.cli.import_cmd:import_group",
    "calibrate": "replay.cli.calibrate:calibrate",
    "cat": "replay.cli.cat:cat",
    "split": "replay.cli.parts:split",
    "merge": "replay.cli.parts:merge",
    "recover": "replay.cli.recover:recover",
    "record": "replay.cli.record:record",
    "simulate": "replay.cli.simulate:simulate",
    "process": "replay.cli.process:process",
    "replay": "replay.cli.replay_log:replay",
    "regress": "replay.cli.regress:regress",
    "demo": "replay.cli.demo:demo",
    "experiment": "replay.cli.experiment:experiment",
}


class BslamGroup(click.Group):
    """A group that imports commands lazily and maps BslamError to one line and exit 1."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(COMMANDS)

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        target = COMMANDS.get(cmd_name)
        if target is None:
            return None
        module_name, attr = target.split(":")
        command: click.Command = getattr(importlib.import_module(module_name), attr)
        return command

    def resolve_command(
        self, ctx: click.Context, args: list[str]
    ) -> tuple[str | None, click.Command | None, list[str]]:
        """Click's lookup; an unknown command suggests the close ones ("Did you mean 'info'?")."""
        name = args[0] if args else ""
        if name and not name.startswith("-") and name not in COMMANDS:
            import difflib

            close = difflib.get_close_matches(name, sorted(COMMANDS), n=3)
            hint = f" Did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
            ctx.fail(f"No such command {name!r}.{hint}")
        return super().resolve_command(ctx, args)

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except BslamError as exc:
            raise click.ClickException(str(exc)) from None

    def main(
        self,
        args: Sequence[str] | None = None,
        prog_name: str | None = None,
        complete_var: str | None = None,
        standalone_mode: bool = True,
        **extra: Any,
    ) -> Any:
        """Run the command; in standalone mode map every way of stopping to an exit code."""
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, False, **extra)
        main_thread = threading.current_thread() is threading.main_thread()
        previous = {}
        if main_thread:
            _stop_signal.clear()
            previous = {
                signal.SIGTERM: signal.signal(signal.SIGTERM, _exit_on_sigterm),
                signal.SIGINT: signal.signal(signal.SIGINT, _interrupt),
            }
            if previous[signal.SIGINT] is signal.SIG_IGN:  # a background job: keep ignoring
                signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            code = super().main(args, prog_name, complete_var, False, **extra)
        except click.UsageError as exc:  # one line and a hint, not the whole usage text
            click.echo(f"Error: {exc.format_message()}", err=True)
            if exc.ctx is not None:
                click.echo(f"Try '{exc.ctx.command_path} --help'.", err=True)
            sys.exit(exc.exit_code)
        except click.ClickException as exc:
            exc.show()
            sys.exit(exc.exit_code)
        except click.Abort:  # click's form of Ctrl-C (KeyboardInterrupt)
            click.echo("interrupted", err=True)
            sys.exit(128 + signal.SIGINT)
        except BaseException as exc:
            signum = getattr(exc, "signum", None)  # recorder.record.RecordingInterrupted
            if isinstance(signum, int):
                click.echo(str(exc), err=True)
                sys.exit(128 + signum)
            if _stop_signal and not isinstance(exc, SystemExit):
                # whatever a stop signal broke on its way (an import it interrupted raises
                # ImportError): the stop, not a traceback
                if _stop_signal[0] == signal.SIGINT:
                    click.echo("interrupted", err=True)
                sys.exit(128 + _stop_signal[0])
            raise
        finally:
            for signum, handler in previous.items():
                signal.signal(signum, handler)
        sys.exit(code if isinstance(code, int) else 0)


def _exit_on_sigterm(signum: int, frame: FrameType | None) -> None:
    """SIGTERM unwinds like Ctrl-C (files closed, workers stopped), then exits 143."""
    _stop_signal.append(signum)
    click.echo("terminated", err=True)
    raise SystemExit(128 + signum)


def _interrupt(signum: int, frame: FrameType | None) -> None:
    """Ctrl-C: Python's KeyboardInterrupt, remembered (see :meth:`BslamGroup.main`)."""
    _stop_signal.append(signum)
    raise KeyboardInterrupt


@click.group(cls=BslamGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="bearing-slam", prog_name="bslam")
def cli() -> None:
    """Bearing-only SLAM with a panoramic camera (impartial PDF, Huang et al. 2007).

    Record sessions to MCAP (or simulate them), process logs into maps, inspect every stage in
    Rerun, rerun stored logs as regression tests, reproduce the paper's experiments.
    """


def main() -> None:
    """Console-script entry point.

    After a stop signal the command has already unwound (logs finished, files closed, workers
    killed); the interpreter's teardown of scipy, matplotlib and Rerun would take about a second
    more, so the process leaves at once after the exit handlers. A command that finished
    ignores stop signals during that teardown and exits with its own code.

    The heap is frozen at exit (``gc.freeze``, the last exit handler to run): Python's final
    collection would walk every object still alive (about 100k after a replay) only to free
    memory the system takes back, 0.2 s of CPU after ``replay --save`` of 100 movements. Every
    output is closed before the command returns; only reference cycles alive at exit go
    unfinalized, which Python does not promise to finalize anyway.
    """
    atexit.register(gc.freeze)
    try:
        cli(prog_name="bslam")
    except SystemExit as exc:
        if exc.code in (128 + signal.SIGINT, 128 + signal.SIGTERM):
            atexit._run_exitfuncs()
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(int(exc.code))
        # the command is done; Python's teardown resets the handlers it installed to the
        # default (a stop signal then kills with no word): ignore stops while it tears down
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, signal.SIG_IGN)
        raise
