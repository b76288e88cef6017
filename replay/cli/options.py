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

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        number = super().convert(value, param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite number.", param, ctx)
        return number


#: Seeds of numpy's random generators: integers >= 0.
SEED = click.IntRange(min=0)
