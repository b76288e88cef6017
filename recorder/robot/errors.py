"""Typed errors of the serial robot driver (all :class:`~data_schemas.errors.RobotError`).

Each message is one line that says what went wrong and what to do; the CLI prints it and exits 1.
"""

from __future__ import annotations

from data_schemas.errors import RobotError


class RobotConfigError(RobotError):
    """A robot setting (baud rate, retries, encoder scale, wheel base) is invalid."""


class SerialPortError(RobotError):
    """The serial port is missing, busy (opened by another program) or not accessible."""


class RobotTimeout(RobotError):
    """The robot did not answer (or did not reach a motion target) in time."""


class GarbledReply(RobotError):
    """The robot answered with bytes that are not a valid reply to the request."""


class RobotProtocolError(RobotError):
    """The robot rejected a request with a ``z,...`` protocol-error reply."""


class RobotDisconnected(RobotError):
    """The serial port went away in the middle of a session (cable, power, USB adapter)."""
