"""KheperaRobot over a real pty against the simulated Khepera: commands, faults, ports."""

from __future__ import annotations

import dataclasses
import os
import termios
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import pytest
import serial

from data_schemas.codec import validate_message
from data_schemas.registry import schema_dict
from data_schemas.stamps import ns_from_stamp
from recorder.clock import VirtualClock
from recorder.robot import (
    GarbledReply,
    KheperaRobot,
    RobotConfig,
    RobotConfigError,
    RobotDisconnected,
    RobotProtocolError,
    RobotTimeout,
    SerialPortError,
    open_serial,
)
from recorder.sim.fake_khepera import FakeKhepera, PtyServer

Log = list[dict[str, Any]]


@pytest.fixture
def clock() -> VirtualClock:
    return VirtualClock()


@pytest.fixture
def fake(clock: VirtualClock) -> FakeKhepera:
    return FakeKhepera(clock, np.random.default_rng(0), initial_pose_world=(0.5, 0.3, 0.0))


@pytest.fixture
def server(fake: FakeKhepera) -> Iterator[PtyServer]:
    with fake.serve_pty() as s:
        yield s


@pytest.fixture
def config(server: PtyServer) -> RobotConfig:
    return RobotConfig(port=server.path, reply_timeout_s=0.2, retries=2, resync_quiet_s=0.02)


@pytest.fixture
def log() -> Log:
    return []


@pytest.fixture
def robot(config: RobotConfig, clock: VirtualClock, log: Log) -> Iterator[KheperaRobot]:
    with KheperaRobot.open(config, clock, on_exchange=log.append) as r:
        yield r


def outcomes(log: Log) -> list[tuple[str, str, int]]:
    for msg in log:
        validate_message("/robot/command", msg)
    return [(m["request"], m["outcome"], m["attempt"]) for m in log]


def test_each_command(
    robot: KheperaRobot, fake: FakeKhepera, clock: VirtualClock, log: Log
) -> None:
    assert robot.version() == "5.02,5.01"
    robot.set_speed(3, -3)
    assert robot.read_speed() == (3, -3)
    status = robot.motion_status()
    assert not status.on_target and not status.left_position_mode
    robot.stop()
    assert robot.read_speed() == (0, 0)
    assert robot.motion_status().on_target
    robot.set_position_counters(100, -50)
    assert robot.read_position_counters() == (100, -50)
    robot.move_to(300, 150)  # 200 pulses each at 20 pulses / 10 ms: 0.1 s
    status = robot.motion_status()
    assert not status.on_target and status.left_position_mode
    assert (status.left_error, status.right_error) == (200, 200)
    assert robot.read_speed() == (20, 20)
    clock.advance_ns(100_000_000)
    status = robot.motion_status()  # done: on target, back in speed control, no error
    assert status.on_target and not status.left_position_mode and status.left_error == 0
    assert robot.read_position_counters() == (300, 150)
    sent = ["B", "D,3,-3", "E", "K", "D,0,0", "E", "K", "G,100,-50", "H", "C,300,150", "K", "E"]
    sent += ["K", "H"]
    assert outcomes(log) == [(r, "ok", 1) for r in sent]
    assert fake.requests == sent
    assert log[1]["reply"] == "d" and log[2]["reply"] == "e,3,-3"


def test_messages_carry_clock_time_and_latency_in_ns(
    robot: KheperaRobot,
    fake: FakeKhepera,
    clock: VirtualClock,
    log: Log,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    answer = fake.handle_line

    def slow(line: bytes) -> Any:  # the device takes 3.456789 ms of clock time per request
        if line.strip():
            clock.advance_ns(3_456_789)
        return answer(line)

    monkeypatch.setattr(fake, "handle_line", slow)
    clock.advance_ns(1_500_000_123)
    robot.read_position_counters()
    fake.inject("timeout", letter="H")  # lost: the clock still moves, no reply
    robot.read_position_counters()
    assert [m["outcome"] for m in log] == ["ok", "timeout", "ok"]
    assert ns_from_stamp(log[0]["timestamp"]) == 1_500_000_123  # when the request was sent
    assert ns_from_stamp(log[1]["timestamp"]) == 1_500_000_123 + 3_456_789
    assert [m["latency_ns"] for m in log] == [3_456_789] * 3
    assert clock.monotonic_ns() == 1_500_000_123 + 3 * 3_456_789
    assert "detail" not in log[0]


def test_timeout_is_retried_after_resync(robot: KheperaRobot, fake: FakeKhepera, log: Log) -> None:
    robot.set_position_counters(7, 8)
    fake.inject("timeout", letter="H")
    assert robot.read_position_counters() == (7, 8)
    assert outcomes(log)[1:] == [("H", "timeout", 1), ("H", "ok", 2)]
    assert "reply" not in log[1] and "no reply" in log[1]["detail"]


def test_garbled_reply_is_retried_after_resync(
    robot: KheperaRobot, fake: FakeKhepera, log: Log
) -> None:
    # the fake leaves stray bytes after the garbled line: only a resync removes them
    fake.inject("garbled", nth=2)
    robot.set_position_counters(7, 8)
    assert robot.read_position_counters() == (7, 8)
    assert outcomes(log) == [("G,7,8", "ok", 1), ("H", "garbled", 1), ("H", "ok", 2)]
    assert log[1]["reply"].startswith("\\xff")


def test_persistent_timeout_gives_up(
    robot: KheperaRobot, fake: FakeKhepera, config: RobotConfig, log: Log
) -> None:
    fake.inject("timeout", times=10)
    with pytest.raises(RobotTimeout, match=f"robot on {config.port} did not answer 'B' after 3"):
        robot.version()
    assert outcomes(log) == [("B", "timeout", a) for a in (1, 2, 3)]
    assert fake.requests == ["B"] * 3


def test_persistent_garbage_gives_up(robot: KheperaRobot, fake: FakeKhepera, log: Log) -> None:
    fake.inject("garbled", letter="K", times=10)
    robot.stop()
    with pytest.raises(GarbledReply, match="garbled replies to 'K' after 3 attempts"):
        robot.motion_status()
    assert outcomes(log)[1:] == [("K", "garbled", a) for a in (1, 2, 3)]
    # the line was resynchronised after the last failure too: the next command starts clean
    assert robot.read_position_counters() == (0, 0)
    assert outcomes(log)[-1] == ("H", "ok", 1)


def test_protocol_error_is_not_retried(robot: KheperaRobot, fake: FakeKhepera, log: Log) -> None:
    fake.inject("protocol_error", letter="D")
    with pytest.raises(RobotProtocolError, match="rejected the D command"):
        robot.set_speed(1, 1)
    assert outcomes(log) == [("D,1,1", "protocol_error", 1)]
    assert log[0]["reply"] == "z,Protocol error"
    assert robot.version() == "5.02,5.01"  # the line is still usable
    assert fake.requests == ["D,1,1", "B"]


def test_mixed_faults_within_the_retry_budget(
    robot: KheperaRobot, fake: FakeKhepera, log: Log
) -> None:
    robot.set_position_counters(1, 2)
    fake.inject("garbled", letter="H")
    fake.inject("timeout", letter="H")
    assert robot.read_position_counters() == (1, 2)
    assert [o for _, o, _ in outcomes(log)] == ["ok", "garbled", "timeout", "ok"]


def test_disconnect_mid_session(
    robot: KheperaRobot, fake: FakeKhepera, server: PtyServer, log: Log
) -> None:
    robot.version()
    robot.stop()
    fake.inject("disconnect", nth=3)
    with pytest.raises(RobotDisconnected, match="disconnected while sending 'H'"):
        robot.read_position_counters()
    assert server.disconnected
    assert outcomes(log)[-1] == ("H", "disconnected", 1)
    assert "reply" not in log[-1] and log[-1]["detail"]
    with pytest.raises(RobotDisconnected, match="lost earlier"):
        robot.stop()
    assert len(log) == 3


def test_disconnect_during_retries(robot: KheperaRobot, fake: FakeKhepera, log: Log) -> None:
    fake.inject("timeout", letter="E")
    fake.inject("disconnect", letter="E")
    with pytest.raises(RobotDisconnected):
        robot.read_speed()
    assert [o for _, o, _ in outcomes(log)] == ["timeout", "disconnected"]


def test_missing_port(tmp_path: Path, clock: VirtualClock) -> None:
    config = RobotConfig(port=str(tmp_path / "ttyUSB9"))
    with pytest.raises(SerialPortError, match="ttyUSB9 does not exist; check the cable"):
        KheperaRobot.open(config, clock)


def test_busy_port(robot: KheperaRobot, config: RobotConfig, clock: VirtualClock) -> None:
    with pytest.raises(SerialPortError, match="is busy"):
        KheperaRobot.open(config, clock)
    assert robot.version() == "5.02,5.01"  # the first user is unaffected


def test_unknown_url_scheme(clock: VirtualClock) -> None:
    with pytest.raises(SerialPortError, match="check the port name"):
        KheperaRobot.open(RobotConfig(port="nope://robot"), clock)


@pytest.mark.parametrize(
    "field, value",
    [("baudrate", 0), ("retries", 11), ("retries", -1), ("mm_per_pulse", 0.0),
     ("wheel_base_m", -0.05), ("reply_timeout_s", 0.0), ("move_speed", 0)],
)  # fmt: skip
def test_bad_config(field: str, value: float) -> None:
    with pytest.raises(RobotConfigError, match="fix the robot settings"):
        RobotConfig(port="/dev/ttyUSB0", **{field: value})


def test_session_dict_matches_the_session_schema() -> None:
    robot_schema = schema_dict("bslam.Session")["properties"]["robot"]
    doc = RobotConfig(port="/dev/ttyUSB0", baudrate=115200).session_dict()
    jsonschema.validate(doc, robot_schema)
    assert doc["baudrate"] == 115200 and doc["stopbits"] == 2


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"baudrate": 14400}, r"runs at 9600, 19200, 38400, 57600, 115200 baud, not 14400"),
        ({"move_speed": 128}, r"move speed 128 exceeds the Khepera II maximum of 127"),
    ],
)
def test_settings_a_khepera_cannot_use_are_refused(
    config: RobotConfig,
    clock: VirtualClock,
    fake: FakeKhepera,
    change: dict[str, int],
    message: str,
) -> None:
    with pytest.raises(RobotConfigError, match=message):
        KheperaRobot.open(dataclasses.replace(config, **change), clock)
    assert fake.requests == []  # refused before anything was sent


@pytest.mark.parametrize("baudrate", [9600, 19200, 38400, 57600, 115200])
def test_every_khepera_baud_rate_is_set_8n2_on_the_port(
    config: RobotConfig, clock: VirtualClock, baudrate: int
) -> None:
    speed = getattr(termios, f"B{baudrate}")  # the pty's termios speed code
    cfg = dataclasses.replace(config, baudrate=baudrate)
    port = open_serial(cfg)
    try:  # the pyserial object itself
        assert isinstance(port, serial.Serial)
        assert (port.baudrate, port.bytesize, port.parity, port.stopbits) == (
            baudrate,
            serial.EIGHTBITS,
            serial.PARITY_NONE,
            serial.STOPBITS_TWO,
        )
    finally:
        port.close()
    with KheperaRobot.open(cfg, clock) as robot:
        fd = os.open(config.port, os.O_RDWR | os.O_NOCTTY)  # what the device was set to
        try:
            _, _, cflag, _, ispeed, ospeed, _ = termios.tcgetattr(fd)
        finally:
            os.close(fd)
        assert robot.version() == "5.02,5.01"
    assert (ispeed, ospeed) == (speed, speed)
    assert cflag & termios.CSIZE == termios.CS8
    assert cflag & termios.CSTOPB and not cflag & termios.PARENB


def test_version_needs_bios_and_protocol_fields(
    robot: KheperaRobot, log: Log, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr("recorder.sim.fake_khepera.VERSION_FIELDS", ("5.02",))
    with pytest.raises(GarbledReply, match="'B'"):
        robot.version()
    assert [o for _, o, _ in outcomes(log)] == ["garbled"] * 3
    assert "should carry 2 fields" in log[0]["detail"]
