"""The movement planner keeps the robot inside the arena and away from landmarks."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from recorder.moves import Move
from recorder.sim.planner import MovePlanner, PlanError
from recorder.sim.scenario import Trajectory, builtin_scenario
from recorder.sim.world import Arena, Pose


class NoisyRobot:
    """Just enough of a robot: executes moves with actuation noise and owns the true pose."""

    def __init__(self, pose: Pose, rng: np.random.Generator) -> None:
        self.pose = pose
        self.rng = rng

    def true_pose(self) -> Pose:
        return self.pose

    def execute(self, move: Move) -> None:
        x, y, h = self.pose
        h += move.turn_rad + self.rng.normal(0.0, math.radians(1.5))
        d = move.distance_m * (1.0 + self.rng.normal(0.0, 0.02))
        self.pose = (x + d * math.cos(h), y + d * math.sin(h), h)


def test_random_moves_stay_in_the_arena_over_many_seeds() -> None:
    base = builtin_scenario("paper")
    scenario = dataclasses.replace(
        base, trajectory=dataclasses.replace(base.trajectory, random_count=40)
    )
    world = scenario.world()
    min_wall, min_landmark = math.inf, math.inf
    for seed in range(40):
        robot = NoisyRobot(scenario.trajectory.start_world, np.random.default_rng(1000 + seed))
        planner = MovePlanner(scenario, robot.true_pose, np.random.default_rng(seed))
        moves = 0
        for move in planner:
            lo, hi = scenario.trajectory.distance_range_m or (0.0, 0.0)
            assert lo <= move.distance_m <= hi
            assert -math.pi <= move.turn_rad < math.pi
            robot.execute(move)
            x, y, _ = robot.pose
            min_wall = min(min_wall, x, y, scenario.arena.width_m - x, scenario.arena.height_m - y)
            gap = world.ranges_m(robot.pose) - world.radius_m
            min_landmark = min(min_landmark, float(gap.min()))
            moves += 1
        assert moves == 40
    # actuation noise may eat into the clearance, never into the robot's radius
    assert min_wall > scenario.robot_radius_m
    assert min_landmark > scenario.robot_radius_m


def test_planner_reads_the_true_pose_before_each_move() -> None:
    scenario = builtin_scenario("paper")
    poses = [(0.05, 0.05, 0.0), (1.0, 0.63, 0.0), (0.05, 0.63, math.pi)]  # corners
    calls = []

    def true_pose() -> Pose:
        pose = poses[len(calls) % len(poses)]
        calls.append(pose)
        return pose

    world = scenario.world()
    planner = MovePlanner(scenario, true_pose, np.random.default_rng(0))
    for i, move in enumerate(planner):
        pose = calls[i]
        assert (
            world.move_problem(
                pose, move.turn_rad, move.distance_m, robot_radius_m=0.03, clearance_m=0.04
            )
            is None
        )
    assert len(calls) == scenario.trajectory.n_moves


def test_planner_gives_up_with_a_clear_error() -> None:
    scenario = dataclasses.replace(
        builtin_scenario("paper"),
        arena=Arena(0.3, 0.3),
        landmarks=(),
        trajectory=Trajectory((0.15, 0.15, 0.0), 3, (0.5, 0.6), None, 0),
    )
    planner = MovePlanner(scenario, lambda: (0.15, 0.15, 0.0), np.random.default_rng(0))
    with pytest.raises(PlanError, match=r"move 0: .*'trajectory\.distance'"):
        list(planner)


def test_explicit_moves_are_played_as_given() -> None:
    moves = (Move(0.5, 0.1), Move(-1.0, 0.15))
    scenario = dataclasses.replace(
        builtin_scenario("paper"),
        trajectory=Trajectory((0.52, 0.34, 0.0), None, None, moves, 0),
    )
    planner = MovePlanner(scenario, lambda: (0.52, 0.34, 0.0), np.random.default_rng(0))
    assert len(planner) == 2
    assert tuple(planner) == moves


def test_same_seed_same_plan() -> None:
    scenario = builtin_scenario("paper")

    def plan(seed: int) -> list[Move]:
        robot = NoisyRobot(scenario.trajectory.start_world, np.random.default_rng(5))
        out = []
        for move in MovePlanner(scenario, robot.true_pose, np.random.default_rng(seed)):
            robot.execute(move)
            out.append(move)
        return out

    assert plan(7) == plan(7)
    assert plan(7) != plan(8)
