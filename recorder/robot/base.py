"""The small interface every serial robot implements, and its configuration.

:class:`Robot` is the shape of the K-Team style ASCII protocols (Khepera, e-puck): speed and
position control of two wheels with encoder counters. A new robot model only has to provide these
methods (see :class:`recorder.robot.khepera.KheperaRobot`); the motion helpers in
:mod:`recorder.robot.motion` and the recorder work with any of them.

Units: wheel speeds in the robot's native unit (Khepera II: pulses per 10 ms), positions and
counters in encoder pulses; :class:`RobotConfig` carries the scale to metres.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

from recorder.robot.errors import RobotConfigError


@dataclass(frozen=True)
class MotionStatus:
    """State of the two wheel controllers (Khepera ``K`` reply).

    Attributes
    ----------
    left_on_target, right_on_target : bool
        Whether each wheel has reached its position target (in speed mode: whether it is stopped).
    left_position_mode, right_position_mode : bool
        True in position control (after ``C``), False in speed control (after ``D``).
    left_error, right_error : int
        Remaining position error (pulses) or speed error (native speed unit).
    """

    left_on_target: bool
    right_on_target: bool
    left_position_mode: bool = True
    right_position_mode: bool = True
    left_error: int = 0
    right_error: int = 0

    @property
    def on_target(self) -> bool:
        """Both wheels reached their targets."""
        return self.left_on_target and self.right_on_target


@dataclass(frozen=True)
class RobotConfig:
    """Serial settings and geometry of a robot (configuration, not constants).

    Defaults are those of a Khepera II: 9600 baud 8N2, 0.08 mm per encoder pulse,
    53 mm between the wheels, position moves at 20 pulses per 10 ms (0.16 m/s).

    Attributes
    ----------
    port : str
        Serial device (``/dev/ttyUSB0``, ``/dev/pts/3``) or pyserial URL.
    model : str
        Robot model name, recorded in the session metadata.
    baudrate : int
        Bits per second.
    bytesize, parity, stopbits :
        Frame format (8 data bits, no parity ``"N"``, 2 stop bits).
    reply_timeout_s : float
        Longest wait for one reply line, seconds.
    retries : int
        Extra attempts after a timeout or garbled reply (0..10); at most ``retries + 1`` tries.
    resync_quiet_s : float
        Resynchronisation drains input until the line has been quiet this long, seconds.
    mm_per_pulse : float
        Wheel travel per encoder pulse, millimetres.
    wheel_base_m : float
        Distance between the two wheel contact points, metres.
    move_speed : int
        Wheel speed of position moves (``C``), native unit (Khepera II: pulses per 10 ms);
        used to bound how long a move may take.
    """

    port: str
    model: str = "khepera2"
    baudrate: int = 9600
    bytesize: int = 8
    parity: str = "N"
    stopbits: float = 2
    reply_timeout_s: float = 0.5
    retries: int = 3
    resync_quiet_s: float = 0.05
    mm_per_pulse: float = 0.08
    wheel_base_m: float = 0.053
    move_speed: int = 20

    def __post_init__(self) -> None:
        checks = [
            (self.baudrate > 0, f"baud rate must be positive, got {self.baudrate}"),
            (self.reply_timeout_s > 0, f"reply timeout must be > 0 s, got {self.reply_timeout_s}"),
            (0 <= self.retries <= 10, f"retries must be 0..10, got {self.retries}"),
            (self.resync_quiet_s > 0, f"quiet time must be > 0 s, got {self.resync_quiet_s}"),
            (self.mm_per_pulse > 0, f"mm per pulse must be > 0, got {self.mm_per_pulse}"),
            (self.wheel_base_m > 0, f"wheel base must be > 0 m, got {self.wheel_base_m}"),
            (self.move_speed > 0, f"move speed must be > 0, got {self.move_speed}"),
        ]
        for ok, message in checks:
            if not ok:
                raise RobotConfigError(f"robot configuration: {message}; fix the robot settings")

    @property
    def m_per_pulse(self) -> float:
        """Wheel travel per encoder pulse, metres."""
        return self.mm_per_pulse / 1000.0

    @property
    def move_speed_m_s(self) -> float:
        """Wheel speed of position moves, m/s (native unit: pulses per 10 ms)."""
        return self.move_speed * 100.0 * self.m_per_pulse

    def session_dict(self) -> dict[str, Any]:
        """The ``robot`` part of the session document (``bslam.Session``)."""
        return {
            "model": self.model,
            "port": self.port,
            "baudrate": self.baudrate,
            "bytesize": self.bytesize,
            "parity": self.parity,
            "stopbits": self.stopbits,
            "mm_per_pulse": self.mm_per_pulse,
            "wheel_base_m": self.wheel_base_m,
        }


class Robot(Protocol):
    """A two-wheeled serial robot (K-Team style ASCII protocol); Khepera letters in brackets."""

    @property
    def config(self) -> RobotConfig:
        """Serial settings and geometry."""
        ...

    def version(self) -> str:
        """Firmware version text (``B``)."""
        ...

    def set_speed(self, left: int, right: int) -> None:
        """Run the wheels at these speeds, native unit (``D``)."""
        ...

    def stop(self) -> None:
        """Stop both wheels (``D,0,0``)."""
        ...

    def set_position_counters(self, left: int, right: int) -> None:
        """Overwrite the encoder counters, pulses (``G``)."""
        ...

    def read_position_counters(self) -> tuple[int, int]:
        """Encoder counters (left, right), pulses (``H``)."""
        ...

    def move_to(self, left: int, right: int) -> None:
        """Start a position move to these counter values, pulses (``C``); returns at once."""
        ...

    def motion_status(self) -> MotionStatus:
        """Controller state, e.g. whether each wheel reached its target (``K``)."""
        ...

    def read_speed(self) -> tuple[int, int]:
        """Instantaneous wheel speeds (left, right), native unit (``E``)."""
        ...

    def close(self) -> None:
        """Release the port (idempotent)."""
        ...
