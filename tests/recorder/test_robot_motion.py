"""turn/drive against the simulated Khepera over a pty: end poses versus kinematics."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest

from recorder.clock import VirtualClock
from recorder.robot import KheperaRobot, MotionStatus, RobotConfig, RobotTimeout, drive, turn
from recorder.robot.motion import move_timeout_s, pulses_for_distance, pulses_for_turn
from recorder.sim.fake_khepera import ActuationNoise, FakeKhepera

START = (0.5, 0.3, 0.2)


Session = tuple[KheperaRobot, FakeKhepera, VirtualClock]


def session(noise: ActuationNoise, seed: int = 0) -> Iterator[Session]:
    clock = VirtualClock()
    fake = FakeKhepera(clock, np.random.default_rng(seed), initial_pose_world=START, noise=noise)
    with fake.serve_pty() as server:
        config = RobotConfig(port=server.path, reply_timeout_s=0.5)
        with KheperaRobot.open(config, clock) as robot:
            yield robot, fake, clock


@pytest.fixture
def exact() -> Iterator[Session]:
    yield from session(ActuationNoise())


@pytest.mark.parametrize("angle_rad", [math.pi / 2, -math.pi / 3, 0.01, math.pi, 0.0])
def test_turn_without_noise(exact: Session, angle_rad: float) -> None:
    robot, fake, clock = exact
    config = robot.config
    left, right = turn(robot, config, angle_rad, clock)
    assert left == -right == -round(angle_rad * config.wheel_base_m / 2 / config.m_per_pulse)
    x, y, heading = fake.pose_world()
    turned = heading - START[2]
    # exact for the commanded pulses; within one pulse per wheel of the asked angle
    assert turned == pytest.approx(2 * right * config.m_per_pulse / config.wheel_base_m, abs=1e-12)
    assert abs(turned - angle_rad) <= config.m_per_pulse / config.wheel_base_m
    assert (x, y) == pytest.approx(START[:2], abs=1e-12)
    assert robot.read_position_counters() == (left, right)


@pytest.mark.parametrize("distance_m", [0.1, 0.25, -0.05, 0.00004])
def test_drive_without_noise(exact: Session, distance_m: float) -> None:
    robot, fake, clock = exact
    config = robot.config
    t0_ns = clock.monotonic_ns()
    left, right = drive(robot, config, distance_m, clock)
    assert left == right == pulses_for_distance(config, distance_m)
    x, y, heading = fake.pose_world()
    travelled = (x - START[0]) * math.cos(START[2]) + (y - START[1]) * math.sin(START[2])
    assert travelled == pytest.approx(left * config.m_per_pulse, abs=1e-12)
    assert abs(travelled - distance_m) <= config.m_per_pulse / 2
    assert heading == START[2]
    # K said "moving" for d / v of virtual time, polled every 0.05 s
    nominal_s = abs(left) / (config.move_speed * 100)
    elapsed_s = (clock.monotonic_ns() - t0_ns) / 1e9
    assert nominal_s <= elapsed_s < nominal_s + 0.05 + 1e-9


def test_turn_then_drive_ends_where_kinematics_says(
    exact: Session,
) -> None:
    robot, fake, clock = exact
    config = robot.config
    _, right = turn(robot, config, math.radians(40), clock)
    left, _ = drive(robot, config, 0.2, clock)
    heading = START[2] + 2 * right * config.m_per_pulse / config.wheel_base_m
    d = left * config.m_per_pulse
    expected = (START[0] + d * math.cos(heading), START[1] + d * math.sin(heading), heading)
    assert tuple(fake.pose_world()) == pytest.approx(expected, abs=1e-12)


def test_on_poll_sees_the_robot_mid_motion(exact: Session) -> None:
    robot, fake, clock = exact
    config = robot.config
    t0_ns = clock.monotonic_ns()
    seen: list[tuple[int, float]] = []

    def grab() -> None:
        x, _, _ = fake.pose_world()
        seen.append((clock.monotonic_ns(), x))

    drive(robot, config, 0.1, clock, poll_s=0.1, on_poll=grab)
    speed_m_s = config.move_speed_m_s * math.cos(START[2])
    assert len(seen) == math.ceil(0.1 / config.move_speed_m_s / 0.1)
    for t_ns, x in seen:
        assert x - START[0] == pytest.approx(speed_m_s * (t_ns - t0_ns) / 1e9, abs=1e-12)


def test_noisy_moves_are_statistically_right() -> None:
    turn_std, distance_std, n = 0.03, 0.05, 120
    turn_ratios, distance_ratios = [], []
    for robot, fake, clock in session(ActuationNoise(turn_std, distance_std), seed=42):
        config = robot.config
        for _ in range(n):
            x0, y0, h0 = fake.pose_world()
            _, right = turn(robot, config, math.pi / 2, clock, poll_s=0.2)
            x1, y1, h1 = fake.pose_world()
            assert (x1, y1) == pytest.approx((x0, y0), abs=1e-12)  # turns in place
            turn_ratios.append((h1 - h0) / (2 * right * config.m_per_pulse / config.wheel_base_m))
            left, _ = drive(robot, config, 0.1, clock, poll_s=0.2)
            x2, y2, h2 = fake.pose_world()
            assert h2 == h1  # straight moves do not turn
            distance_ratios.append(math.hypot(x2 - x1, y2 - y1) / (left * config.m_per_pulse))
    for ratios, std in ((turn_ratios, turn_std), (distance_ratios, distance_std)):
        r = np.asarray(ratios)
        assert abs(r.mean() - 1.0) < 4 * std / math.sqrt(n)
        assert r.std(ddof=1) == pytest.approx(std, rel=0.25)


class StuckRobot:
    """A robot whose wheels never reach their target (blocked), for the motion timeout."""

    def __init__(self, config: RobotConfig) -> None:
        self.config = config
        self.calls: list[str] = []

    def set_position_counters(self, left: int, right: int) -> None:
        self.calls.append(f"G,{left},{right}")

    def move_to(self, left: int, right: int) -> None:
        self.calls.append(f"C,{left},{right}")

    def motion_status(self) -> MotionStatus:
        return MotionStatus(False, True)

    def stop(self) -> None:
        self.calls.append("D,0,0")


def test_blocked_wheels_stop_the_robot_and_raise() -> None:
    config, clock = RobotConfig(port="/dev/ttyUSB0"), VirtualClock()
    robot = StuckRobot(config)
    with pytest.raises(RobotTimeout, match="did not reach its target"):
        drive(robot, config, 0.1, clock)  # type: ignore[arg-type]
    pulses = pulses_for_distance(config, 0.1)
    assert robot.calls == ["G,0,0", f"C,{pulses},{pulses}", "D,0,0"]
    assert clock.monotonic_ns() / 1e9 == pytest.approx(move_timeout_s(config, pulses), abs=0.06)


def test_pulse_conversions() -> None:
    config = RobotConfig(port="x", mm_per_pulse=0.1, wheel_base_m=0.1)
    assert pulses_for_distance(config, 0.25) == 2500
    assert pulses_for_turn(config, math.pi) == round(math.pi * 0.05 / 1e-4)
