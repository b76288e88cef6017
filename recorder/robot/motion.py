"""Turn in place and drive straight with position moves (``G`` + ``C``, then ``K`` polling).

Both helpers zero the encoder counters, command a position move, and poll the motion status
every ``poll_s`` seconds with ``clock.sleep`` (so they run in virtual time against the simulated
robot) until both wheels are on target. ``on_poll`` is called once per poll, e.g. to capture a
camera frame during the motion. A move that takes far longer than its nominal duration at
``config.move_speed`` stops the robot and raises :class:`RobotTimeout`.

Geometry (differential drive): a turn by ``angle_rad`` (CCW positive) moves the right wheel
forward and the left wheel backward by ``angle_rad * wheel_base_m / 2`` each; a straight move of
``distance_m`` moves both wheels by ``distance_m``. Commands are rounded to whole encoder pulses.
"""

from __future__ import annotations

from collections.abc import Callable

from recorder.clock import Clock
from recorder.robot.base import Robot, RobotConfig
from recorder.robot.errors import RobotConfigError, RobotTimeout

#: Slack added to twice the nominal duration of a move before it counts as stuck, seconds.
MOVE_TIMEOUT_SLACK_S = 2.0


#: The largest wheel travel of one position move, pulses (the robot's signed 32-bit counter).
MAX_PULSES = 2**31 - 1


def _whole_pulses(travel: float, what: str) -> int:
    """``travel`` (pulses) rounded, refused unless the robot's counter can hold it."""
    if not abs(travel) <= MAX_PULSES:  # also NaN and infinities
        raise RobotConfigError(
            f"{what} needs {travel:.3g} encoder pulses, beyond the robot's counter "
            f"({MAX_PULSES}); ask for a shorter move or check --mm-per-pulse"
        )
    return round(travel)


def pulses_for_distance(config: RobotConfig, distance_m: float) -> int:
    """Wheel travel for a straight move of ``distance_m`` metres, whole pulses.

    Raises
    ------
    RobotConfigError
        The travel does not fit the robot's position counter (:data:`MAX_PULSES`).
    """
    return _whole_pulses(distance_m / config.m_per_pulse, f"a drive of {distance_m:.3g} m")


def pulses_for_turn(config: RobotConfig, angle_rad: float) -> int:
    """Right-wheel travel (left = minus this) for a turn in place by ``angle_rad``, whole pulses.

    Raises
    ------
    RobotConfigError
        The travel does not fit the robot's position counter (:data:`MAX_PULSES`).
    """
    travel = angle_rad * config.wheel_base_m / 2.0 / config.m_per_pulse
    return _whole_pulses(travel, f"a turn of {angle_rad:.3g} rad")


def move_timeout_s(config: RobotConfig, pulses: int) -> float:
    """Longest a position move of ``pulses`` (largest wheel) may take, seconds."""
    nominal_s = abs(pulses) / (config.move_speed * 100.0)
    return 2.0 * nominal_s + MOVE_TIMEOUT_SLACK_S


def turn(
    robot: Robot,
    config: RobotConfig,
    angle_rad: float,
    clock: Clock,
    *,
    poll_s: float = 0.05,
    on_poll: Callable[[], None] | None = None,
) -> tuple[int, int]:
    """Turn in place by ``angle_rad`` (CCW positive) and wait until done.

    Returns
    -------
    (int, int)
        Commanded (left, right) wheel travel, pulses (left = -right).
    """
    pulses = pulses_for_turn(config, angle_rad)
    return _move(robot, config, clock, -pulses, pulses, poll_s, on_poll)


def drive(
    robot: Robot,
    config: RobotConfig,
    distance_m: float,
    clock: Clock,
    *,
    poll_s: float = 0.05,
    on_poll: Callable[[], None] | None = None,
) -> tuple[int, int]:
    """Drive straight ``distance_m`` metres (negative = backwards) and wait until done.

    Returns
    -------
    (int, int)
        Commanded (left, right) wheel travel, pulses (equal).
    """
    pulses = pulses_for_distance(config, distance_m)
    return _move(robot, config, clock, pulses, pulses, poll_s, on_poll)


def _move(
    robot: Robot,
    config: RobotConfig,
    clock: Clock,
    left: int,
    right: int,
    poll_s: float,
    on_poll: Callable[[], None] | None,
) -> tuple[int, int]:
    robot.set_position_counters(0, 0)
    robot.move_to(left, right)
    timeout_s = move_timeout_s(config, max(abs(left), abs(right)))
    t0_ns = clock.monotonic_ns()
    while not robot.motion_status().on_target:
        if clock.monotonic_ns() - t0_ns > timeout_s * 1e9:
            robot.stop()
            raise RobotTimeout(
                f"robot on {config.port} did not reach its target ({left}, {right}) pulses "
                f"within {timeout_s:.1f} s; check that the wheels are free and not blocked"
            )
        if on_poll is not None:
            on_poll()
        clock.sleep(poll_s)
    return left, right
