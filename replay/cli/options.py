"""Click parameter types and options shared by the commands: finite numbers, seeds, windows and
the method (:func:`method_options`).

Click's ``FloatRange`` lets ``nan`` and ``inf`` through (``nan`` compares false with any bound,
``inf`` passes a lower bound); every float a user types goes through :class:`FiniteFloat`
instead, so a command refuses them as a usage error (exit 2) before doing anything.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Any

import click

from replay import defaults


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


#: Largest particle counts: FR keeps n_r^2 observation points per movement (2000: 64 MB).
MAX_N_R = 2_000
MAX_N_L = 100_000

n_r_option = click.option(
    "--n-r",
    "n_r",
    type=click.IntRange(2, MAX_N_R),
    default=defaults.N_R,
    show_default=True,
    help="Particles per landmark in FR.",
)
n_l_option = click.option(
    "--n-l",
    "n_l",
    type=click.IntRange(2, MAX_N_L),
    default=defaults.N_L,
    show_default=True,
    help="Particles per landmark in FL.",
)

estimator_option = click.option(
    "--estimator",
    type=click.Choice(defaults.ESTIMATORS),
    default=defaults.ESTIMATOR,
    show_default=True,
    help="joint: every bearing in one factor graph (GTSAM), initialized by the paper's filter; "
    "paper: the paper's filter alone.",
)


def _zero_is_off(ctx: click.Context, param: click.Parameter, value: float) -> float | None:
    return value or None


distance_prior_option = click.option(
    "--distance-prior",
    "distance_prior",
    type=FiniteFloat(min=0.0),
    callback=_zero_is_off,
    default=defaults.DISTANCE_PRIOR_REL or 0.0,
    show_default=True,
    metavar="FRACTION",
    help="Joint estimator: trust each movement's driven distance (odometry, else the "
    "commanded distance) to this relative std; 0 leaves the lengths free.",
)


#: Options of the driving estimator (logs with bearings and odometry); None: its defaults.
driving_method_options = [
    click.option(
        "--keyframe-distance",
        "keyframe_distance_m",
        type=FiniteFloat(min=0.0, min_open=True),
        default=None,
        metavar="M",
        help="Driving logs: a keyframe every M metres of odometry path [default: 0.3].",
    ),
    click.option(
        "--keyframe-turn",
        "keyframe_turn_deg",
        type=FiniteFloat(min=0.0, min_open=True),
        default=None,
        metavar="DEG",
        help="Driving logs: or every DEG degrees of turning [default: 20].",
    ),
    click.option(
        "--odometry-std",
        "odometry_std_per_m",
        type=FiniteFloat(min=0.0, min_open=True),
        default=None,
        metavar="M_PER_M",
        help="Driving logs: odometry position std per metre of path [default: 0.1].",
    ),
    click.option(
        "--odometry-heading-std",
        "odometry_heading_std_per_rad",
        type=FiniteFloat(min=0.0, min_open=True),
        default=None,
        metavar="RAD_PER_RAD",
        help="Driving logs: odometry heading std per radian turned [default: 0.2].",
    ),
    click.option(
        "--keyframe-window",
        "keyframe_window",
        type=click.IntRange(min=0),
        default=defaults.KEYFRAME_WINDOW,
        show_default=True,
        metavar="KEYFRAMES",
        help="Driving logs: keep the newest KEYFRAMES keyframes in the graph and marginalize "
        "older ones (cost per keyframe stays flat on long drives; less accurate with narrow "
        "views); 0 keeps every keyframe.",
    ),
]


#: The options of :func:`method_options`, in --help order.
_METHOD_OPTIONS = [
    estimator_option,
    click.option(
        "--turn-prior",
        "turn_prior_deg",
        type=click.FloatRange(0.0, min_open=True),
        default=defaults.TURN_PRIOR_DEG,
        metavar="DEG",
        help="Joint estimator: trust each commanded turn in place to this std "
        "(degrees) [default: turns free].",
    ),
    distance_prior_option,
    click.option(
        "--window",
        "window",
        type=click.IntRange(min=0),
        default=defaults.JOINT_WINDOW,
        show_default=True,
        metavar="MOVEMENTS",
        help="Joint estimator: keep the newest MOVEMENTS movements in the graph (at least 50) "
        "and marginalize older ones (cost per movement stays flat on long logs); 0 keeps "
        "every movement.",
    ),
    click.option(
        "--prior",
        type=click.Choice(defaults.PRIORS),
        default=defaults.PRIOR,
        show_default=True,
        help="Density of one bearing: the paper's impartial PDF or a baseline.",
    ),
    n_r_option,
    n_l_option,
    click.option(
        "--seed",
        type=SEED,
        default=defaults.SEED,
        show_default=True,
        help="Seed of the estimator's random generator.",
    ),
    *driving_method_options,
]


#: The options' parameter names: the fields of ``replay.records.MethodConfig`` they set.
_METHOD_FIELDS = (
    "estimator",
    "turn_prior_deg",
    "distance_prior",
    "prior",
    "n_r",
    "n_l",
    "seed",
    "keyframe_distance_m",
    "keyframe_turn_deg",
    "odometry_std_per_m",
    "odometry_heading_std_per_rad",
    "window",
    "keyframe_window",
)


def method_options(fn: Callable[..., Any]) -> Callable[..., Any]:
    """The estimator options shared by process and replay, passed to ``fn`` as one ``method``.

    ``fn`` takes ``method: replay.records.MethodConfig`` (built from the options, whose names
    are MethodConfig's fields) instead of the options one by one.
    """

    @functools.wraps(fn)
    def with_method(*args: Any, **kwargs: Any) -> Any:
        from replay.records import MethodConfig

        fields = {name: kwargs.pop(name) for name in _METHOD_FIELDS}
        return fn(*args, method=MethodConfig(**fields), **kwargs)

    command: Callable[..., Any] = with_method
    for option in reversed(_METHOD_OPTIONS):
        command = option(command)
    return command
