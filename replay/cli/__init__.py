"""The ``bslam`` command line: one click group whose commands load on demand.

Each command lives in its own module and is imported only when it runs (or when ``--help``
lists it), so ``bslam --help`` stays fast and ``bslam record`` on a robot never imports scipy or
Rerun. Commands only compose library calls. Any :class:`~data_schemas.errors.BslamError` becomes
one line on stderr and exit code 1; usage errors exit 2 (click's convention).
"""

from __future__ import annotations

import importlib
from typing import Any

import click

from data_schemas.errors import BslamError

#: command name -> "module:attribute". Add a command by adding a line here.
COMMANDS: dict[str, str] = {
    "info": "replay.cli.info:info",
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

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except BslamError as exc:
            raise click.ClickException(str(exc)) from None


@click.group(cls=BslamGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="bearing-slam", prog_name="bslam")
def cli() -> None:
    """Bearing-only SLAM with a panoramic camera (impartial PDF, Huang et al. 2007).

    Record sessions to MCAP (or simulate them), process logs into maps, inspect every stage in
    Rerun, rerun stored logs as regression tests, reproduce the paper's experiments.
    """


def main() -> None:
    """Console-script entry point."""
    cli(prog_name="bslam")
