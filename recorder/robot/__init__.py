"""Serial robot drivers: the :class:`~recorder.robot.base.Robot` interface, the Khepera (II)
driver, its ASCII protocol, typed errors and turn/drive helpers.

Public API (stable)::

    from recorder.robot import KheperaRobot, RobotConfig, open_serial, turn, drive
"""

from __future__ import annotations

from recorder.robot.base import MotionStatus, Robot, RobotConfig
from recorder.robot.errors import (
    GarbledReply,
    RobotConfigError,
    RobotDisconnected,
    RobotProtocolError,
    RobotTimeout,
    SerialPortError,
)
from recorder.robot.khepera import KheperaRobot, OnExchange, open_serial
from recorder.robot.motion import drive, turn

__all__ = [
    "GarbledReply",
    "KheperaRobot",
    "MotionStatus",
    "OnExchange",
    "Robot",
    "RobotConfig",
    "RobotConfigError",
    "RobotDisconnected",
    "RobotProtocolError",
    "RobotTimeout",
    "SerialPortError",
    "drive",
    "open_serial",
    "turn",
]
