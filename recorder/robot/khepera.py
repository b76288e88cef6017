"""Serial driver for the Khepera (II) robot: :func:`open_serial` and :class:`KheperaRobot`.

Usage::

    config = RobotConfig(port="/dev/ttyUSB0")
    with KheperaRobot.open(config, SystemClock(), on_exchange=writer_callback) as robot:
        robot.version()            # "5.02,5.01"
        robot.set_speed(5, -5)     # D,5,-5
        robot.stop()               # D,0,0

Every attempt of every exchange is reported to ``on_exchange`` as a ``/robot/command`` message
dict (``bslam.RobotCommand``): time stamp from the injected clock (monotonic), request and reply
lines, outcome (``ok``, ``timeout``, ``garbled``, ``protocol_error``, ``disconnected``), latency
and attempt number. A timeout or garbled reply is retried at most ``config.retries`` times, each
after resynchronising the line (flush input, send a bare CR, drain until quiet); the line is
also resynchronised after the last failed attempt, so the next command starts clean. A ``z`` reply
(protocol error) is not retried: the line is resynchronised and :class:`RobotProtocolError`
raised. A port that vanishes raises :class:`RobotDisconnected`. Not thread-safe: one caller.
"""

from __future__ import annotations

import contextlib
import errno
import sys
from collections.abc import Callable
from typing import Any, Protocol, cast

import serial

from data_schemas.closing import Closing
from data_schemas.stamps import stamp_from_ns
from recorder.clock import Clock
from recorder.robot.base import MotionStatus, RobotConfig
from recorder.robot.errors import (
    GarbledReply,
    RobotConfigError,
    RobotDisconnected,
    RobotProtocolError,
    RobotTimeout,
    SerialPortError,
)
from recorder.robot.protocol import Reply, encode_request, int_fields, parse_reply

#: Receives each ``/robot/command`` message dict.
OnExchange = Callable[[dict[str, Any]], None]

_MISSING = {errno.ENOENT, errno.ENODEV, errno.ENXIO}
_BUSY = {errno.EAGAIN, errno.EWOULDBLOCK, errno.EBUSY}
_DENIED = {errno.EACCES, errno.EPERM}
_DRAIN_MAX_READS = 64
if sys.platform == "win32":
    _LinkErrors: tuple[type[Exception], ...] = (serial.SerialException, OSError)
else:
    import termios

    # pyserial lets termios.error (not an OSError) escape from a hung-up port
    _LinkErrors = (serial.SerialException, OSError, termios.error)


#: Baud rates of the Khepera II serial protocol (its running-mode switch picks one), 8N2.
BAUDRATES = (9600, 19200, 38400, 57600, 115200)
#: Largest wheel speed, pulses per 10 ms (127 x 8 mm/s: about 1 m/s).
MAX_SPEED = 127


def check_khepera_config(config: RobotConfig) -> None:
    """Raise :class:`RobotConfigError` for settings a Khepera II cannot use."""
    if config.baudrate not in BAUDRATES:
        rates = ", ".join(str(b) for b in BAUDRATES)
        raise RobotConfigError(
            f"the Khepera II serial protocol runs at {rates} baud, not {config.baudrate}; "
            "set --baud to the rate of the robot's running mode"
        )
    if config.move_speed > MAX_SPEED:
        raise RobotConfigError(
            f"move speed {config.move_speed} exceeds the Khepera II maximum of {MAX_SPEED} "
            "pulses per 10 ms; lower it"
        )


def _port_error(port: str, exc: Exception) -> SerialPortError:
    code = getattr(exc, "errno", None)
    if code in _MISSING:
        return SerialPortError(
            f"serial port {port} does not exist; check the cable and the port name "
            "(ls /dev/ttyUSB* /dev/ttyACM*)"
        )
    if code in _BUSY:
        return SerialPortError(
            f"serial port {port} is busy (another program has it open); "
            f"close that program (see `fuser {port}`) and retry"
        )
    if code in _DENIED:
        return SerialPortError(
            f"no permission to open serial port {port}; add your user to the 'dialout' group"
        )
    return SerialPortError(f"cannot open serial port {port} ({exc}); check the port name")


class SerialPort(Protocol):
    """What the driver needs of a pyserial port (``serial.Serial`` or a URL handler's class)."""

    timeout: float | None

    def write(self, data: bytes, /) -> int | None: ...
    def read(self, size: int = 1, /) -> bytes: ...
    def read_until(self, expected: bytes = ..., size: int | None = ...) -> bytes: ...
    def reset_input_buffer(self) -> None: ...
    def close(self) -> None: ...


def open_serial(config: RobotConfig) -> SerialPort:
    """Open ``config.port`` (device path or pyserial URL) exclusively, 8N2, with timeouts.

    Raises
    ------
    SerialPortError
        The port is missing, busy, not accessible or rejects the settings.
    """
    try:
        port = serial.serial_for_url(
            config.port,
            do_not_open=True,
            baudrate=config.baudrate,
            bytesize=config.bytesize,
            parity=config.parity,
            stopbits=config.stopbits,
            timeout=config.reply_timeout_s,
            write_timeout=config.reply_timeout_s,
            exclusive=True,
        )
        port.open()
    except (serial.SerialException, OSError) as exc:
        raise _port_error(config.port, exc) from None
    except ValueError as exc:
        raise SerialPortError(
            f"cannot use serial port {config.port} ({exc}); check the port name and settings"
        ) from None
    return cast(SerialPort, port)


class KheperaRobot(Closing):
    """A Khepera (II) over an open serial port; implements :class:`recorder.robot.base.Robot`.

    Parameters
    ----------
    port : SerialPort
        Open port (see :func:`open_serial`); the robot owns and closes it.
    config : RobotConfig
        Settings (retries, timeouts, geometry).
    clock : Clock
        Time stamps and latencies of the ``/robot/command`` messages.
    on_exchange : callable, optional
        Called with each ``/robot/command`` message dict.
    """

    def __init__(
        self,
        port: SerialPort,
        config: RobotConfig,
        clock: Clock,
        on_exchange: OnExchange | None = None,
    ) -> None:
        self._port = port
        self._config = config
        self._clock = clock
        self._on_exchange = on_exchange
        self._disconnected = False

    @classmethod
    def open(
        cls, config: RobotConfig, clock: Clock, on_exchange: OnExchange | None = None
    ) -> KheperaRobot:
        """Check the settings, open ``config.port`` (:func:`open_serial`), discard stale input.

        Raises
        ------
        RobotConfigError
            A baud rate the Khepera II does not speak, or a move speed above its maximum.
        SerialPortError
            The port is missing, busy or not accessible.
        """
        check_khepera_config(config)
        port = open_serial(config)
        try:
            port.reset_input_buffer()
        except _LinkErrors as exc:
            port.close()
            raise _port_error(config.port, exc) from None
        return cls(port, config, clock, on_exchange)

    @property
    def config(self) -> RobotConfig:
        """Serial settings and geometry."""
        return self._config

    def close(self) -> None:
        """Close the port (idempotent)."""
        with contextlib.suppress(*_LinkErrors):
            self._port.close()

    # ------------------------------------------------------------------ commands
    def version(self) -> str:
        """BIOS and protocol versions, e.g. ``"5.02,5.01"`` (``B`` -> ``b,5.02,5.01``)."""
        return ",".join(self.command("B", n_fields=2).fields[:2])

    def set_speed(self, left: int, right: int) -> None:
        """Wheel speeds in pulses per 10 ms (``D``)."""
        self.command("D", left, right)

    def stop(self) -> None:
        """Stop both wheels (``D,0,0``)."""
        self.set_speed(0, 0)

    def set_position_counters(self, left: int, right: int) -> None:
        """Overwrite the encoder counters, pulses (``G``)."""
        self.command("G", left, right)

    def read_position_counters(self) -> tuple[int, int]:
        """Encoder counters (left, right), pulses (``H``)."""
        left, right = int_fields(self.command("H", n_ints=2), 2)
        return left, right

    def move_to(self, left: int, right: int) -> None:
        """Start a position move to these counter values, pulses (``C``)."""
        self.command("C", left, right)

    def motion_status(self) -> MotionStatus:
        """Controller state (``K`` -> ``k,T_l,M_l,E_l,T_r,M_r,E_r``), per wheel.

        T = 1 on target (0 moving), M = 0 position control / 1 speed control, E = position or
        speed error. A finished ``C`` move reads T = 1, M = 1 (the controller is back in speed
        mode at rest), so only T tells that a move is done.
        """
        t_l, m_l, e_l, t_r, m_r, e_r = int_fields(self.command("K", n_ints=6), 6)
        return MotionStatus(t_l == 1, t_r == 1, m_l == 0, m_r == 0, e_l, e_r)

    def read_speed(self) -> tuple[int, int]:
        """Instantaneous wheel speeds (left, right), pulses per 10 ms (``E``)."""
        left, right = int_fields(self.command("E", n_ints=2), 2)
        return left, right

    # ------------------------------------------------------------------ exchange
    def command(self, letter: str, *args: int, n_ints: int = 0, n_fields: int = 0) -> Reply:
        """Send one request and return its reply, with bounded retries.

        Parameters
        ----------
        letter : str
            Upper-case command letter.
        *args : int
            Arguments.
        n_ints : int
            The reply must carry at least this many integer fields (else it counts as garbled).
        n_fields : int
            The reply must carry at least this many fields of any kind (else garbled).

        Raises
        ------
        RobotTimeout, GarbledReply
            Still failing after ``config.retries`` retries.
        RobotProtocolError
            The robot answered ``z,...`` (not retried).
        RobotDisconnected
            The port went away.
        """
        request = encode_request(letter, *args)
        text = request[:-1].decode("ascii")
        cfg = self._config
        if self._disconnected:
            raise self._disconnect_error(text, "the port was lost earlier")
        attempts = cfg.retries + 1
        failure: tuple[RobotTimeout | GarbledReply, str | None] | None = None
        for attempt in range(1, attempts + 1):
            t0_ns = self._clock.monotonic_ns()
            try:
                self._port.write(request)
                raw = self._port.read_until(b"\n")
            except serial.SerialTimeoutException:
                raw = b""
            except _LinkErrors as exc:
                self._report(t0_ns, text, None, "disconnected", attempt, str(exc))
                self._disconnected = True
                raise self._disconnect_error(text, str(exc)) from None
            reply_text = raw.rstrip(b"\r\n").decode("ascii", "backslashreplace") if raw else None
            try:
                if not raw.endswith(b"\n"):
                    if raw:
                        raise GarbledReply(f"incomplete reply {reply_text!r} (no CR LF)")
                    raise RobotTimeout(f"no reply within {cfg.reply_timeout_s} s")
                reply = parse_reply(raw, letter)
                if n_ints:
                    int_fields(reply, n_ints)
                if len(reply.fields) < n_fields:
                    raise GarbledReply(f"reply {reply.text!r} should carry {n_fields} fields")
            except RobotProtocolError as exc:
                self._report(t0_ns, text, reply_text, "protocol_error", attempt, str(exc))
                self._resync(attempt)
                raise
            except (RobotTimeout, GarbledReply) as exc:
                outcome = "timeout" if isinstance(exc, RobotTimeout) else "garbled"
                self._report(t0_ns, text, reply_text, outcome, attempt, str(exc))
                failure = (exc, reply_text)
                self._resync(attempt)  # also after the last one: leave the line clean
                continue
            self._report(t0_ns, text, reply_text, "ok", attempt, None)
            return reply
        assert failure is not None  # every attempt failed
        raise self._final_error(failure[0], text, attempts, failure[1])

    def _final_error(
        self, exc: RobotTimeout | GarbledReply, text: str, attempts: int, reply_text: str | None
    ) -> RobotTimeout | GarbledReply:
        cfg = self._config
        if isinstance(exc, RobotTimeout):
            return RobotTimeout(
                f"robot on {cfg.port} did not answer {text!r} after {attempts} attempts; "
                f"check that it is switched on, in serial-protocol mode, at {cfg.baudrate} baud"
            )
        return GarbledReply(
            f"robot on {cfg.port} gave garbled replies to {text!r} after {attempts} attempts "
            f"(last {reply_text!r}); check the baud rate ({cfg.baudrate}) and the cable"
        )

    def _disconnect_error(self, text: str, why: str) -> RobotDisconnected:
        return RobotDisconnected(
            f"robot on {self._config.port} disconnected while sending {text!r} ({why}); "
            "check the cable and power, then start a new recording"
        )

    def _report(
        self,
        t0_ns: int,
        request: str,
        reply: str | None,
        outcome: str,
        attempt: int,
        detail: str | None,
    ) -> None:
        if self._on_exchange is None:
            return
        msg: dict[str, Any] = {
            "timestamp": stamp_from_ns(t0_ns),
            "request": request,
            "outcome": outcome,
            "latency_ns": max(0, self._clock.monotonic_ns() - t0_ns),
            "attempt": attempt,
        }
        if reply is not None:  # no reply: the field is absent (optional in the schema)
            msg["reply"] = reply
        if detail is not None:
            msg["detail"] = detail
        self._on_exchange(msg)

    def _resync(self, attempt: int) -> None:
        """Flush input, send a bare CR, drain until the line is quiet (disconnect if it fails)."""
        t0_ns = self._clock.monotonic_ns()
        port = self._port
        try:
            port.reset_input_buffer()
            port.write(b"\r")
            saved = port.timeout
            port.timeout = self._config.resync_quiet_s
            try:
                for _ in range(_DRAIN_MAX_READS):
                    if not port.read(4096):
                        break
            finally:
                port.timeout = saved
        except serial.SerialTimeoutException:
            return
        except _LinkErrors as exc:
            detail = f"while resynchronising after attempt {attempt}: {exc}"
            self._report(t0_ns, "", None, "disconnected", attempt, detail)
            self._disconnected = True
            raise self._disconnect_error("a resynchronising CR", str(exc)) from None
