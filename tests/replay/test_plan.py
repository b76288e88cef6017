"""The movement plan: keyframes, commanded turns and the distance each movement drove."""

from __future__ import annotations

from pathlib import Path

import pytest

from data_schemas.mcap.processable import ProcessableLog
from data_schemas.registry import MOVEMENT_TOPIC, ODOMETRY_TOPIC
from data_schemas.stamps import stamp_from_ns
from replay.plan import MovementPlan, read_plan

REGRESS = Path(__file__).resolve().parents[1] / "data" / "regress"


def _movement(t_ns: int, index: int, phase: str, distance_m: float) -> dict[str, object]:
    return {
        "timestamp": stamp_from_ns(t_ns),
        "index": index,
        "phase": phase,
        "keyframe_timestamp": stamp_from_ns(t_ns),
        "turn_rad": 0.5,
        "distance_m": distance_m,
    }


def _odometry(t_ns: int, left: int, right: int, mm: float | None = 0.08) -> dict[str, object]:
    doc: dict[str, object] = {"timestamp": stamp_from_ns(t_ns), "left_pulses": left}
    doc["right_pulses"] = right
    if mm is not None:
        doc["mm_per_pulse"] = mm
    return doc


def test_distance_is_the_odometry_of_the_drive_else_the_command() -> None:
    plan = MovementPlan()
    # movement 0: the turn's counters at start (wheels opposite), the drive's at end (stopped
    # short: 1500 of the commanded 2000 pulses)
    plan.add(ODOMETRY_TOPIC, _odometry(10, -400, 400))
    plan.add(MOVEMENT_TOPIC, _movement(10, 0, "start", 0.16))
    assert plan.distances_m[0] == pytest.approx(0.16)  # the command until the drive is known
    plan.add(ODOMETRY_TOPIC, _odometry(20, 1490, 1510))
    plan.add(MOVEMENT_TOPIC, _movement(20, 0, "end", 0.16))
    assert plan.distances_m[0] == pytest.approx(0.12)
    assert plan.turns_rad[0] == 0.5
    # movement 1: no odometry logged; movement 2: odometry without its scale
    plan.add(MOVEMENT_TOPIC, _movement(30, 1, "start", 0.2))
    plan.add(MOVEMENT_TOPIC, _movement(40, 1, "end", 0.2))
    plan.add(ODOMETRY_TOPIC, _odometry(60, 1000, 1000, mm=None))
    plan.add(MOVEMENT_TOPIC, _movement(60, 2, "end", 0.25))
    assert plan.distances_m[1] == pytest.approx(0.2)
    assert plan.distances_m[2] == pytest.approx(0.25)
    # odometry at another time stamp is not this movement's
    plan.add(ODOMETRY_TOPIC, _odometry(69, 10, 10))
    plan.add(MOVEMENT_TOPIC, _movement(70, 3, "end", 0.1))
    assert plan.distances_m[3] == pytest.approx(0.1)


def test_simulated_log_drives_its_commanded_distance_to_a_pulse() -> None:
    # the simulated robot's encoders reach the commanded count (its slip moves the robot, not
    # the wheels), so odometry and command agree to one pulse (0.08 mm) in simulation
    with ProcessableLog(REGRESS / "unwrapped.mcap") as log:
        plan = read_plan(log)
        commanded = {
            int(d["index"]): float(d["distance_m"])
            for d in (m.decode() for m in log.messages((MOVEMENT_TOPIC,)))
        }
        n_odometry = sum(1 for _ in log.messages((ODOMETRY_TOPIC,)))
    assert n_odometry == 2 * len(commanded)  # at both keyframes of every movement
    assert plan.distances_m.keys() == commanded.keys() and len(commanded) >= 3
    for k, d in commanded.items():
        assert plan.distances_m[k] == pytest.approx(d, abs=1e-4)
