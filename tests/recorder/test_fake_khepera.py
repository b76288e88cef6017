"""The simulated Khepera: protocol state machine, kinematics in clock time, faults, pty."""

from __future__ import annotations

import math
import os
import select
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from recorder.clock import SystemClock, VirtualClock
from recorder.robot import KheperaRobot, RobotConfig
from recorder.robot.protocol import encode_reply, encode_request
from recorder.sim.fake_khepera import ActuationNoise, FakeKhepera, PtyServer

ROOT = Path(__file__).resolve().parents[2]
Z = encode_reply("z", "Protocol error")


def make(clock: VirtualClock, pose: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> FakeKhepera:
    return FakeKhepera(clock, np.random.default_rng(0), initial_pose_world=pose)


def ask(fake: FakeKhepera, letter: str, *args: int) -> bytes | None:
    return fake.handle_line(encode_request(letter, *args)).data


def test_k_reports_moving_for_d_over_v_of_clock_time() -> None:
    clock = VirtualClock()
    fake = make(clock)
    assert ask(fake, "C", 1000, 1000) == b"c\r\n"  # 1000 pulses at 2000 pulses/s: 0.5 s
    clock.advance_ns(250_000_000)
    assert ask(fake, "K") == b"k,0,0,500,0,0,500\r\n"
    assert ask(fake, "E") == b"e,20,20\r\n"
    clock.advance_ns(249_999_999)
    assert ask(fake, "K") == b"k,0,0,0,0,0,0\r\n"
    clock.advance_ns(1)
    assert ask(fake, "K") == b"k,1,1,0,1,1,0\r\n"  # done: on target, back in speed mode
    assert ask(fake, "E") == b"e,0,0\r\n"
    assert ask(fake, "H") == b"h,1000,1000\r\n"
    assert fake.pose_world() == pytest.approx((0.08, 0.0, 0.0), abs=1e-15)


def test_speed_mode_integrates_until_changed() -> None:
    clock = VirtualClock()
    fake = make(clock, (1.0, 2.0, math.pi / 2))
    ask(fake, "D", 10, 10)  # 1000 pulses/s = 0.08 m/s
    assert ask(fake, "K") == b"k,0,1,0,0,1,0\r\n"
    clock.advance_ns(2_000_000_000)
    assert ask(fake, "H") == b"h,2000,2000\r\n"
    ask(fake, "D", 0, 0)
    clock.advance_ns(5_000_000_000)
    assert ask(fake, "K") == b"k,1,1,0,1,1,0\r\n"
    assert fake.pose_world() == pytest.approx((1.0, 2.16, math.pi / 2), abs=1e-12)


def test_arc_matches_numerical_integration() -> None:
    clock = VirtualClock()
    cfg = RobotConfig(port="x")
    fake = FakeKhepera(clock, np.random.default_rng(0), initial_pose_world=(0.1, 0.2, 0.3))
    ask(fake, "C", 500, 1500)  # right wheel sets the duration: 0.75 s; one arc
    clock.advance_ns(750_000_000)
    vl, vr = 500 / 0.75 * cfg.m_per_pulse, 1500 / 0.75 * cfg.m_per_pulse
    x, y, th = 0.1, 0.2, 0.3
    steps = 20000
    dt = 0.75 / steps
    for _ in range(steps):  # midpoint rule
        th_mid = th + 0.5 * dt * (vr - vl) / cfg.wheel_base_m
        x += dt * 0.5 * (vl + vr) * math.cos(th_mid)
        y += dt * 0.5 * (vl + vr) * math.sin(th_mid)
        th += dt * (vr - vl) / cfg.wheel_base_m
    assert fake.pose_world() == pytest.approx((x, y, th), abs=1e-9)


def test_pose_history_and_interpolation() -> None:
    clock = VirtualClock()
    fake = make(clock, (0.5, 0.5, 0.0))
    t_start = clock.monotonic_ns()
    ask(fake, "C", 2000, 2000)  # 1 s, 0.16 m
    clock.advance_ns(250_000_000)
    quarter = fake.pose_world()
    assert quarter == pytest.approx((0.54, 0.5, 0.0))
    clock.advance_ns(2_000_000_000)
    ask(fake, "G", 0, 0)
    ask(fake, "C", -520, 520)  # a turn after the drive
    clock.advance_ns(1_000_000_000)
    assert fake.pose_world(t_start + 250_000_000) == quarter
    assert fake.pose_world(t_start) == (0.5, 0.5, 0.0)
    assert fake.pose_world()[2] == pytest.approx(2 * 520 * 0.08e-3 / 0.053)
    with pytest.raises(ValueError, match="before the simulated robot started"):
        fake.pose_world(t_start - 1)


def test_set_counters_during_a_move_keeps_the_remaining_travel() -> None:
    clock = VirtualClock()
    fake = make(clock)
    ask(fake, "C", 1000, 1000)
    clock.advance_ns(250_000_000)
    assert ask(fake, "H") == b"h,500,500\r\n"
    ask(fake, "G", 0, 0)
    assert ask(fake, "K") == b"k,0,0,500,0,0,500\r\n"
    clock.advance_ns(250_000_000)
    assert ask(fake, "H") == b"h,500,500\r\n"
    assert fake.pose_world()[0] == pytest.approx(0.08)


def test_noise_is_drawn_per_motion_from_the_injected_rng() -> None:
    ends = []
    for seed in (1, 1, 2):
        clock = VirtualClock()
        fake = FakeKhepera(clock, np.random.default_rng(seed), noise=ActuationNoise(0.05, 0.05))
        ask(fake, "C", 1000, 1000)
        clock.advance_ns(10**9)
        assert ask(fake, "H") == b"h,1000,1000\r\n"  # encoders reach the target exactly
        ends.append(fake.pose_world()[0])
    assert ends[0] == ends[1] != ends[2]
    assert ends[0] != pytest.approx(0.08, abs=1e-9)
    with pytest.raises(ValueError, match=">= 0"):
        ActuationNoise(-0.1, 0.0)


@pytest.mark.parametrize(
    "line", [b"X\r", b"H,1\r", b"D,1\r", b"C\r", b"d,1,1\r", b"D,1.5,2\r", b"\xfe\r"]
)
def test_unknown_or_malformed_requests_get_z(line: bytes) -> None:
    assert make(VirtualClock()).handle_line(line).data == Z


def test_bare_cr_is_ignored_and_not_counted() -> None:
    fake = make(VirtualClock())
    assert fake.handle_line(b"\r").data is None
    assert fake.requests == []


def test_fault_selection_by_nth_letter_and_times() -> None:
    fake = make(VirtualClock())
    fake.inject("timeout", nth=3)
    fake.inject("protocol_error", letter="h", times=2)
    fake.inject("garbled", nth=6, letter="B")
    got = [ask(fake, letter) for letter in "BBHHHBBB"]
    version = b"b,5.02,5.01\r\n"
    assert got[0] == got[1] == version
    assert got[2] is None  # the third request is lost
    assert got[3] == got[4] == Z  # the next two H
    assert got[5] is not None and got[5].startswith(b"\xff\xe2\xac")  # the first B from the 6th
    assert got[6] == got[7] == version
    with pytest.raises(ValueError, match="unknown fault"):
        fake.inject("explode")  # type: ignore[arg-type]


def test_pty_serves_cr_or_lf_lines_and_closes_cleanly() -> None:
    fake = make(VirtualClock())
    server = PtyServer(fake)
    fd = os.open(server.path, os.O_RDWR | os.O_NOCTTY)
    try:
        os.write(fd, b"B\rG,4,5\nH\r")
        want = b"b,5.02,5.01\r\ng\r\nh,4,5\r\n"
        got = b""
        while len(got) < len(want) and select.select([fd], [], [], 2.0)[0]:
            got += os.read(fd, 100)
        assert got == want
    finally:
        os.close(fd)
        server.close()
        server.close()
    assert server.disconnected


def test_disconnect_fault_removes_the_port() -> None:
    clock = VirtualClock()
    fake = make(clock)
    with fake.serve_pty() as server:
        fake.inject("disconnect", letter="B")
        fd = os.open(server.path, os.O_RDWR | os.O_NOCTTY)
        try:
            os.write(fd, b"B\r")
            assert select.select([fd], [], [], 2.0)[0]
            assert os.read(fd, 10) == b""  # hang-up, as pyserial sees an unplugged adapter
            assert not os.path.exists(server.path)
            with pytest.raises(OSError):
                os.write(fd, b"B\r")
        finally:
            os.close(fd)
        assert server.disconnected


def test_module_serves_a_pty_until_ctrl_c() -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "recorder.sim.fake_khepera", "--seed", "3"],
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        path = line.split(" on ")[1].split()[0]
        with KheperaRobot.open(RobotConfig(port=path), SystemClock()) as robot:
            assert robot.version() == "5.02,5.01"
            robot.set_position_counters(12, 34)
            assert robot.read_position_counters() == (12, 34)
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=10)
        assert proc.returncode == 0
        assert "final true pose" in out
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
