"""The movement plan of a simulated session: which turn and straight distance comes next.

Each move turns the robot in place, then drives it straight. With random moves (a count in
the scenario), the turn is uniform in [-pi, pi) and the distance uniform in the scenario's
range; a draw whose straight path, predicted from the robot's current TRUE pose, would end
closer than the robot radius to a wall or pass too close to a landmark is drawn again (up to
``max_tries`` times, then :class:`PlanError`). Explicit moves are checked when the scenario is
loaded (from the start pose, dead-reckoned) and are played as given.

The true pose comes from a callable (the simulated robot owns it), read just before each move
is drawn, so actuation noise does not accumulate into the safety check.

Public API
----------
:class:`MovePlanner` (iterate it to get :class:`~recorder.moves.Move` objects),
:class:`PlanError`.

Example::

    planner = MovePlanner(scenario, robot.true_pose, np.random.default_rng(seed))
    for move in planner:
        robot.turn(move.turn_rad)
        robot.drive(move.distance_m)
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator

import numpy as np

from data_schemas.errors import ScenarioError
from recorder.moves import Move
from recorder.sim.scenario import CLEARANCE_M, Scenario
from recorder.sim.world import Pose


class PlanError(ScenarioError):
    """No safe random move could be drawn (the arena is too small for the distance range)."""


class MovePlanner:
    """The moves of a scenario's trajectory, drawn lazily from the robot's true pose.

    Parameters
    ----------
    scenario : Scenario
        Arena, landmarks, robot radius and trajectory.
    true_pose : callable () -> (x, y, heading)
        The robot's current true pose, world frame (m, m, rad).
    rng : numpy.random.Generator
        Source of the random moves (e.g. ``default_rng(scenario.trajectory.seed)``).
    clearance_m : float
        Gap kept between the robot's edge and a landmark's surface along a straight path.
    max_tries : int
        Draws per random move before giving up with :class:`PlanError`.
    """

    def __init__(
        self,
        scenario: Scenario,
        true_pose: Callable[[], Pose],
        rng: np.random.Generator,
        *,
        clearance_m: float = CLEARANCE_M,
        max_tries: int = 1000,
    ) -> None:
        self.scenario = scenario
        self._world = scenario.world()
        self._true_pose = true_pose
        self._rng = rng
        self.clearance_m = clearance_m
        self.max_tries = max_tries

    def __len__(self) -> int:
        return self.scenario.trajectory.n_moves

    def __iter__(self) -> Iterator[Move]:
        traj = self.scenario.trajectory
        if traj.moves is not None:
            yield from traj.moves
            return
        for index in range(len(self)):
            yield self._draw(index)

    def _draw(self, index: int) -> Move:
        """A random move that is safe from the current true pose."""
        traj = self.scenario.trajectory
        assert traj.distance_range_m is not None
        lo, hi = traj.distance_range_m
        pose = self._true_pose()
        for _ in range(self.max_tries):
            turn = float(self._rng.uniform(-math.pi, math.pi))
            distance = float(self._rng.uniform(lo, hi))
            problem = self._world.move_problem(
                pose,
                turn,
                distance,
                robot_radius_m=self.scenario.robot_radius_m,
                clearance_m=self.clearance_m,
            )
            if problem is None:
                return Move(turn, distance)
        raise PlanError(
            f"move {index}: no turn and distance in [{lo:g}, {hi:g}] m keeps the robot inside "
            f"the arena and clear of landmarks from ({pose[0]:.3f}, {pose[1]:.3f}) m after "
            f"{self.max_tries} tries; shorten key 'trajectory.distance'"
        )
