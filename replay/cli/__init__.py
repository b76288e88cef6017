"""The ``bslam`` command line: one click group whose commands load on demand.

Each command lives in its own module and is imported only when it runs (or when ``--help``
lists it), so ``bslam --help`` stays fast and ``bslam record`` on a robot never imports scipy or
Rerun. Commands only compose library calls. Any :class:`~data_schemas.errors.BslamError` becomes
one line on stderr and exit code 1; a usage error is one line and a hint to ``--help``, exit 2
(click's convention). Ctrl-C exits 130; SIGTERM stops the command the same way (exit 143):
open files are closed, worker processes are stopped, a log being recorded is finished.
"""

from __future__ import annotations

import atexit
import importlib
import os
import signal
import sys
import threading
from collections.abc import Sequence
from types import FrameType
from typing import Any

import click

from data_schemas.errors import BslamError

#: command name -> "module:attribute". Add a command by adding a line here.
COMMANDS: dict[str, str] = {
    "info": "replay.cli.info:info",
    "import": "replay.cli.import_cmd:import_group",
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
        previous = signal.signal(signal.SIGTERM, _exit_on_sigterm) if main_thread else None
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
            if not isinstance(signum, int):
                raise
            click.echo(str(exc), err=True)
            sys.exit(128 + signum)
        finally:
            if main_thread:
                signal.signal(signal.SIGTERM, previous)
        sys.exit(code if isinstance(code, int) else 0)


def _exit_on_sigterm(signum: int, frame: FrameType | None) -> None:
    """SIGTERM unwinds like Ctrl-C (files closed, workers stopped), then exits 143."""
    click.echo("terminated", err=True)
    raise SystemExit(128 + signum)


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
    more, so the process leaves at once after the exit handlers.
    """
    try:
        cli(prog_name="bslam")
    except SystemExit as exc:
        if exc.code in (128 + signal.SIGINT, 128 + signal.SIGTERM):
            atexit._run_exitfuncs()
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(int(exc.code))
        raise
