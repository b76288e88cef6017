"""A simulated Khepera (II) that speaks the serial protocol, served on a pseudo-terminal.

:class:`FakeKhepera` is the robot: a protocol state machine (encoder counters, wheel speeds,
position targets) whose motion progresses in the injected clock's time, and differential-drive
kinematics that integrate the TRUE pose ``(x, y, heading)`` in the world frame (m, rad, CCW).
A position move (``C``) runs both wheels at ``config.move_speed`` (the longer wheel path sets the
duration; both wheels finish together, so every move is one arc): a move of d metres takes
``d / config.move_speed_m_s`` seconds of clock time and ``K`` reports "moving" until then.
Encoders reach their targets exactly; the true motion differs by actuation noise: for each
motion command, the rotation is scaled by ``1 + N(0, turn_scale_std)`` and the forward travel by
``1 + N(0, distance_scale_std)`` (drawn from the injected ``rng``).

:class:`PtyServer` serves a fake robot on a real serial endpoint (``/dev/pts/N``, raw mode) from a
background thread, so :class:`recorder.robot.khepera.KheperaRobot` talks to it through real
pyserial. Faults for tests: :meth:`FakeKhepera.inject`. Usage::

    clock = VirtualClock()
    fake = FakeKhepera(clock, np.random.default_rng(1), initial_pose_world=(0.5, 0.3, 0.0))
    with fake.serve_pty() as server:
        config = RobotConfig(port=server.path)
        with KheperaRobot.open(config, clock) as robot:
            drive(robot, config, 0.1, clock)
        fake.pose_world()          # true pose now; pose_world(t_ns) at any earlier clock time

``python -m recorder.sim.fake_khepera`` serves one on a pty (real time) until Ctrl-C.
"""

from __future__ import annotations

import argparse
import bisect
import math
import os
import select
import threading
import tty
from dataclasses import dataclass
from typing import Literal, NamedTuple

import numpy as np

from data_schemas.closing import Closing
from recorder.clock import Clock, SystemClock
from recorder.robot.base import RobotConfig
from recorder.robot.errors import RobotProtocolError
from recorder.robot.protocol import Request, encode_reply, parse_request

#: Reply to ``B``.
VERSION_FIELDS = ("5.02", "5.01")
#: Reply to a request the robot does not understand.
PROTOCOL_ERROR_REPLY = encode_reply("z", "Protocol error")

FaultKind = Literal["timeout", "garbled", "protocol_error", "disconnect"]
_FAULT_KINDS = ("timeout", "garbled", "protocol_error", "disconnect")


class PoseWorld(NamedTuple):
    """True robot pose in the world frame: metres and radians (CCW, heading wrapped freely)."""

    x: float
    y: float
    heading: float


@dataclass(frozen=True)
class ActuationNoise:
    """Relative 1-sigma scale errors applied to each motion command (0 = exact)."""

    turn_scale_std: float = 0.0
    distance_scale_std: float = 0.0

    def __post_init__(self) -> None:
        if self.turn_scale_std < 0 or self.distance_scale_std < 0:
            raise ValueError(f"noise standard deviations must be >= 0, got {self}")


@dataclass(frozen=True)
class Response:
    """What the robot does with one request line: send ``data`` (None = stay silent), or hang up."""

    data: bytes | None
    disconnect: bool = False


@dataclass
class _Fault:
    kind: FaultKind
    nth: int | None
    letter: str | None
    remaining: int

    def matches(self, count: int, letter: str) -> bool:
        return (
            self.remaining > 0
            and (self.nth is None or count >= self.nth)
            and (self.letter is None or self.letter == letter)
        )


@dataclass(frozen=True)
class _Segment:
    """Motion with constant wheel rates from ``t0_ns`` until ``t1_ns`` (None = until changed)."""

    t0_ns: int
    t1_ns: int | None
    counters0: tuple[float, float]
    rates_pps: tuple[float, float]
    target: tuple[int, int] | None  # position mode: counters at t1_ns; None = speed mode
    pose0: PoseWorld
    v_m_s: float
    omega_rad_s: float

    def _tau_s(self, t_ns: int) -> float:
        end = t_ns if self.t1_ns is None else min(t_ns, self.t1_ns)
        return max(0, end - self.t0_ns) / 1e9

    def finished(self, t_ns: int) -> bool:
        return self.t1_ns is not None and t_ns >= self.t1_ns

    def counters(self, t_ns: int) -> tuple[float, float]:
        if self.target is not None and self.finished(t_ns):
            return float(self.target[0]), float(self.target[1])
        tau = self._tau_s(t_ns)
        return (
            self.counters0[0] + self.rates_pps[0] * tau,
            self.counters0[1] + self.rates_pps[1] * tau,
        )

    def moving(self, t_ns: int) -> bool:
        return self.rates_pps != (0.0, 0.0) and not self.finished(t_ns)

    def pose(self, t_ns: int) -> PoseWorld:
        tau = self._tau_s(t_ns)
        x0, y0, th0 = self.pose0
        dth = self.omega_rad_s * tau
        if abs(dth) < 1e-12:
            d = self.v_m_s * tau
            return PoseWorld(x0 + d * math.cos(th0), y0 + d * math.sin(th0), th0)
        radius = self.v_m_s / self.omega_rad_s
        return PoseWorld(
            x0 + radius * (math.sin(th0 + dth) - math.sin(th0)),
            y0 - radius * (math.cos(th0 + dth) - math.cos(th0)),
            th0 + dth,
        )


def _garble(reply: bytes) -> bytes:
    """Corrupt a reply the way line noise does: high bits set, and stray bytes after the CR LF.

    The stray bytes stay in the client's input buffer: only a resynchronisation removes them.
    """
    body = reply.rstrip(b"\r\n")
    return b"\xff" + bytes(b | 0x80 for b in body) + b"\r\n\x80\xfe"


class FakeKhepera:
    """A simulated Khepera (II): protocol state machine plus true differential-drive kinematics.

    Parameters
    ----------
    clock : Clock
        Time base of the motion (``VirtualClock`` for simulation).
    rng : numpy.random.Generator
        Source of the actuation noise.
    initial_pose_world : (float, float, float)
        True start pose ``(x, y, heading)``, m and rad, world frame.
    config : RobotConfig, optional
        Geometry (``mm_per_pulse``, ``wheel_base_m``) and ``move_speed``; Khepera II defaults.
    noise : ActuationNoise, optional
        Scale errors of turns and distances; none by default.

    Thread-safe: the transport thread calls :meth:`handle_line` while a simulated camera calls
    :meth:`pose_world`.
    """

    def __init__(
        self,
        clock: Clock,
        rng: np.random.Generator,
        *,
        initial_pose_world: tuple[float, float, float] = (0.0, 0.0, 0.0),
        config: RobotConfig | None = None,
        noise: ActuationNoise | None = None,
    ) -> None:
        self._clock = clock
        self._rng = rng
        self._config = config if config is not None else RobotConfig(port="fake-khepera")
        self._noise = noise if noise is not None else ActuationNoise()
        self._lock = threading.Lock()
        self._faults: list[_Fault] = []
        self._requests: list[str] = []
        start = _Segment(
            t0_ns=clock.monotonic_ns(),
            t1_ns=None,
            counters0=(0.0, 0.0),
            rates_pps=(0.0, 0.0),
            target=None,
            pose0=PoseWorld(*(float(v) for v in initial_pose_world)),
            v_m_s=0.0,
            omega_rad_s=0.0,
        )
        self._segments: list[_Segment] = [start]
        self._starts_ns: list[int] = [start.t0_ns]

    @property
    def config(self) -> RobotConfig:
        """Geometry and move speed of the simulated robot."""
        return self._config

    @property
    def requests(self) -> list[str]:
        """Every non-empty request line received so far, in order (without CR)."""
        with self._lock:
            return list(self._requests)

    def serve_pty(self) -> PtyServer:
        """Serve this robot on a new pseudo-terminal (see :class:`PtyServer`)."""
        return PtyServer(self)

    # ------------------------------------------------------------------ faults
    def inject(
        self,
        kind: FaultKind,
        *,
        nth: int | None = None,
        letter: str | None = None,
        times: int = 1,
    ) -> None:
        """Arm a fault for the next ``times`` matching requests.

        Parameters
        ----------
        kind : {"timeout", "garbled", "protocol_error", "disconnect"}
            ``timeout``: the request is lost (not executed, no reply). ``garbled``: executed, but
            the reply bytes are corrupted. ``protocol_error``: not executed, reply ``z,...``.
            ``disconnect``: the port goes away (the transport hangs up).
        nth : int, optional
            Start at the nth request received (1-based, counting retries); default the next one.
        letter : str, optional
            Only requests with this command letter (e.g. ``"H"``).
        times : int
            How many matching requests are affected.
        """
        if kind not in _FAULT_KINDS:
            raise ValueError(f"unknown fault {kind!r}; expected one of {_FAULT_KINDS}")
        if times < 1:
            raise ValueError(f"times must be >= 1, got {times}")
        with self._lock:
            self._faults.append(_Fault(kind, nth, letter.upper() if letter else None, times))

    def _take_fault(self, count: int, letter: str) -> FaultKind | None:
        for fault in self._faults:
            if fault.matches(count, letter):
                fault.remaining -= 1
                return fault.kind
        return None

    # ------------------------------------------------------------------ protocol
    def handle_line(self, line: bytes) -> Response:
        """React to one request line (terminator optional), at the clock's current time."""
        if not line.strip(b"\r\n \t"):
            return Response(None)  # bare CR (resynchronisation): ignored
        with self._lock:
            now_ns = self._clock.monotonic_ns()
            self._requests.append(line.rstrip(b"\r\n").decode("ascii", "backslashreplace"))
            try:
                request = parse_request(line)
            except RobotProtocolError:
                return Response(PROTOCOL_ERROR_REPLY)
            fault = self._take_fault(len(self._requests), request.letter)
            if fault == "timeout":
                return Response(None)
            if fault == "protocol_error":
                return Response(PROTOCOL_ERROR_REPLY)
            if fault == "disconnect":
                return Response(None, disconnect=True)
            reply = self._execute(request, now_ns)
            return Response(_garble(reply) if fault == "garbled" else reply)

    def _execute(self, request: Request, now_ns: int) -> bytes:
        letter, args = request.letter, request.args
        seg = self._segments[-1]
        if letter == "B" and not args:
            return encode_reply("b", *VERSION_FIELDS)
        if letter in "CDG" and len(args) == 2:
            left, right = args
            if letter == "C":
                self._start_move(now_ns, (left, right))
            elif letter == "D":
                self._start_speed(now_ns, (left, right))
            else:
                self._set_counters(now_ns, (left, right))
            return encode_reply(letter.lower())
        if letter == "H" and not args:
            left_f, right_f = seg.counters(now_ns)
            return encode_reply("h", round(left_f), round(right_f))
        if letter == "E" and not args:
            moving = seg.moving(now_ns)
            left_s, right_s = (round(r / 100.0) if moving else 0 for r in seg.rates_pps)
            return encode_reply("e", left_s, right_s)
        if letter == "K" and not args:
            return encode_reply("k", *self._status_fields(seg, now_ns))
        return PROTOCOL_ERROR_REPLY

    def _status_fields(self, seg: _Segment, now_ns: int) -> list[int]:
        counters = seg.counters(now_ns)
        fields: list[int] = []
        for wheel in (0, 1):
            if seg.target is not None and not seg.finished(now_ns):
                # position move under way: T=0, M=0 (position control), E = pulses to go
                fields += [0, 0, round(seg.target[wheel] - counters[wheel])]
            elif seg.target is not None:
                # a finished move leaves the controller in speed mode at rest (K-Team's kMatlab
                # example reads "AT TARGET, SPEED" after kMoveTo)
                fields += [1, 1, 0]
            else:  # speed mode: on target when stopped, M=1, E = 0
                fields += [1 if seg.rates_pps[wheel] == 0 else 0, 1, 0]
        return fields

    # ------------------------------------------------------------------ kinematics
    def _push(self, segment: _Segment) -> None:
        self._segments.append(segment)
        self._starts_ns.append(segment.t0_ns)

    def _true_rates(self, rates_pps: tuple[float, float]) -> tuple[float, float]:
        """True forward speed (m/s) and turn rate (rad/s) of wheel rates, with noise drawn."""
        cfg = self._config
        turn_scale = 1.0 + self._rng.normal(0.0, self._noise.turn_scale_std)
        distance_scale = 1.0 + self._rng.normal(0.0, self._noise.distance_scale_std)
        v_left, v_right = (r * cfg.m_per_pulse for r in rates_pps)
        v = 0.5 * (v_left + v_right) * distance_scale
        omega = (v_right - v_left) / cfg.wheel_base_m * turn_scale
        return float(v), float(omega)

    def _start_motion(
        self,
        now_ns: int,
        rates_pps: tuple[float, float],
        t1_ns: int | None,
        target: tuple[int, int] | None,
    ) -> None:
        """New motion segment from the current state, with fresh actuation noise."""
        seg = self._segments[-1]
        v, omega = self._true_rates(rates_pps)
        self._push(
            _Segment(
                t0_ns=now_ns,
                t1_ns=t1_ns,
                counters0=seg.counters(now_ns),
                rates_pps=rates_pps,
                target=target,
                pose0=seg.pose(now_ns),
                v_m_s=v,
                omega_rad_s=omega,
            )
        )

    def _start_move(self, now_ns: int, target: tuple[int, int]) -> None:
        """Position move (``C``): both wheels finish together at ``config.move_speed``."""
        counters = self._segments[-1].counters(now_ns)
        deltas = (target[0] - counters[0], target[1] - counters[1])
        duration_s = max(abs(d) for d in deltas) / (self._config.move_speed * 100.0)
        rates = (deltas[0] / duration_s, deltas[1] / duration_s) if duration_s > 0 else (0.0, 0.0)
        self._start_motion(now_ns, rates, now_ns + round(duration_s * 1e9), target)

    def _start_speed(self, now_ns: int, speeds: tuple[int, int]) -> None:
        """Speed mode (``D``): wheels run at ``speeds`` pulses per 10 ms until changed."""
        self._start_motion(now_ns, (speeds[0] * 100.0, speeds[1] * 100.0), None, None)

    def _set_counters(self, now_ns: int, values: tuple[int, int]) -> None:
        """Overwrite the counters; a move in progress keeps its remaining travel."""
        seg = self._segments[-1]
        counters = seg.counters(now_ns)
        shift = (values[0] - counters[0], values[1] - counters[1])
        target = seg.target
        if target is not None:
            target = (round(target[0] + shift[0]), round(target[1] + shift[1]))
        self._push(
            _Segment(
                t0_ns=now_ns,
                t1_ns=seg.t1_ns,
                counters0=(float(values[0]), float(values[1])),
                rates_pps=seg.rates_pps,
                target=target,
                pose0=seg.pose(now_ns),
                v_m_s=seg.v_m_s,
                omega_rad_s=seg.omega_rad_s,
            )
        )

    def pose_world(self, t_ns: int | None = None) -> PoseWorld:
        """True pose at time ``t_ns`` (default now), interpolated within a motion.

        ``t_ns`` is in the time base of the clock given to the constructor (its
        ``monotonic_ns``), e.g. the ``VirtualClock`` the recorder also sleeps on.

        Raises
        ------
        ValueError
            ``t_ns`` is before the robot was created.
        """
        with self._lock:
            t = self._clock.monotonic_ns() if t_ns is None else int(t_ns)
            i = bisect.bisect_right(self._starts_ns, t) - 1
            if i < 0:
                raise ValueError(f"no pose at {t} ns: before the simulated robot started")
            return self._segments[i].pose(t)


class PtyServer(Closing):
    """Serve a :class:`FakeKhepera` on a new pseudo-terminal from a background thread.

    ``path`` (``/dev/pts/N``) is a real serial endpoint for pyserial. Request lines end with CR
    (or LF). A ``disconnect`` fault closes the pty, so the client's next read or write fails as
    with an unplugged cable. Use as a context manager, or call :meth:`close` (idempotent).
    """

    def __init__(self, fake: FakeKhepera) -> None:
        self._fake = fake
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        self.path: str = os.ttyname(self._slave)
        self._wake_r, self._wake_w = os.pipe()
        self._pty_open = True
        self._closed = False
        self._thread = threading.Thread(
            target=self._serve, name=f"fake-khepera {self.path}", daemon=True
        )
        self._thread.start()

    @property
    def disconnected(self) -> bool:
        """Whether the pty was closed (by a ``disconnect`` fault or :meth:`close`)."""
        return not self._pty_open

    def close(self) -> None:
        """Stop the thread and close the pty (idempotent)."""
        if self._closed:
            return
        self._closed = True
        os.write(self._wake_w, b"x")
        self._thread.join()
        self._close_pty()
        os.close(self._wake_r)
        os.close(self._wake_w)

    def _close_pty(self) -> None:
        if self._pty_open:
            self._pty_open = False
            os.close(self._master)
            os.close(self._slave)

    def _serve(self) -> None:
        pending = b""
        while True:
            ready, _, _ = select.select([self._master, self._wake_r], [], [])
            if self._wake_r in ready:
                return
            try:
                pending += os.read(self._master, 4096).replace(b"\n", b"\r")
            except OSError:
                return
            while b"\r" in pending:
                line, pending = pending.split(b"\r", 1)
                response = self._fake.handle_line(line)
                if response.disconnect:
                    self._close_pty()
                    return
                if response.data:
                    os.write(self._master, response.data)


def main(argv: list[str] | None = None) -> None:
    """Serve a simulated Khepera on a pty in real time; print its path; stop on Ctrl-C."""
    parser = argparse.ArgumentParser(
        prog="python -m recorder.sim.fake_khepera", description=main.__doc__
    )
    parser.add_argument("--seed", type=int, default=0, help="actuation-noise seed")
    parser.add_argument("--turn-noise", type=float, default=0.02, help="turn scale std")
    parser.add_argument("--distance-noise", type=float, default=0.02, help="distance scale std")
    args = parser.parse_args(argv)
    clock = SystemClock()
    fake = FakeKhepera(
        clock,
        np.random.default_rng(args.seed),
        noise=ActuationNoise(args.turn_noise, args.distance_noise),
    )
    with fake.serve_pty() as server:
        try:  # from the announcement on: a Ctrl-C right after it still ends cleanly
            print(f"simulated Khepera on {server.path} (Ctrl-C to stop)", flush=True)
            while True:
                clock.sleep(3600)
        except KeyboardInterrupt:
            print(f"final true pose (x, y, heading): {tuple(fake.pose_world())}", flush=True)


if __name__ == "__main__":
    main()
