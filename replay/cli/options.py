"""Click parameter types shared by the commands: finite numbers and seeds.

Click's ``FloatRange`` lets ``nan`` and ``inf`` through (``nan`` compares false with any bound,
``inf`` passes a lower bound); every float a user types goes through :class:`FiniteFloat`
instead, so a command refuses them as a usage error (exit 2) before doing anything.
"""

from __future__ import annotations

import math
from typing import Any

import click


class FiniteFloat(click.FloatRange):
    """A float that must be finite, optionally within bounds (same arguments as FloatRange)."""

    name = "finite float"

    def _describe_range(self) -> str:
        """Click's ``[x<=None]`` for a float without bounds: nothing to show."""
        return "" if self.min is None and self.max is None else super()._describe_range()

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        if not math.isfinite(click.FLOAT.convert(value, param, ctx)):  # before the range
            self.fail(f"{value!r} is not a finite number.", param, ctx)
        return super().convert(value, param, ctx)


#: Seeds of numpy's random generators: integers >= 0.
SEED = click.IntRange(min=0)


class WindowBound(click.ParamType):
    """``--from`` / ``--to``: ``12.5s`` (seconds from the log's start) or ``m3`` (movement 3)."""

    name = "Ns|mK"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        from data_schemas.mcap.window import Bound, WindowError, parse_bound

        if isinstance(value, Bound):
            return value
        try:
            return parse_bound(str(value))
        except WindowError as exc:
            self.fail(str(exc), param, ctx)


def window_options(fn: click.decorators.FC) -> click.decorators.FC:
    """``--from`` and ``--to`` (passed as ``start`` and ``end``, Bound or None)."""
    fn = click.option(
        "--to",
        "end",
        type=WindowBound(),
        help="Stop after this point: seconds from the log's start ('60s') or the end of a "
        "movement ('m5', included).",
    )(fn)
    return click.option(
        "--from",
        "start",
        type=WindowBound(),
        help="Start at this point: seconds from the log's start ('10s') or the start of a "
        "movement ('m2', included).",
    )(fn)
