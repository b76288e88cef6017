"""The movements of a log: which frames are keyframes, and the simulator's true poses.

``/robot/movement`` has a ``start`` and an ``end`` message per straight movement; each points at
its keyframe through ``keyframe_timestamp``, equal to that frame's ``timestamp``.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from data_schemas.stamps import ns_from_stamp
from replay.logs import ProcessableLog

MOVEMENT_TOPIC = "/robot/movement"
TRUTH_TOPIC = "/sim/ground_truth"
PHASES = ("start", "end")


@dataclass
class MovementPlan:
    """Keyframe time stamps of every movement, and the true poses of a simulated log.

    Attributes
    ----------
    keyframes : dict index -> {"start": ns, "end": ns}
        Keyframe ``timestamp`` of each phase that was logged.
    truth_times_ns : list of int
        Sorted ``/sim/ground_truth`` time stamps (empty for a real log).
    truth_poses : (n, 3) float
        Matching ``x, y, heading`` (m, m, rad; world frame).
    turns_rad : dict index -> float
        Commanded turn in place before each movement (CCW, rad).
    """

    keyframes: dict[int, dict[str, int]] = field(default_factory=dict)
    turns_rad: dict[int, float] = field(default_factory=dict)
    truth_times_ns: list[int] = field(default_factory=list)
    truth_poses: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))

    def keys_at(self) -> dict[int, list[tuple[int, str]]]:
        """Frame time stamp -> the (index, phase) keyframes it is."""
        out: dict[int, list[tuple[int, str]]] = {}
        for index in sorted(self.keyframes):
            for phase, t_ns in self.keyframes[index].items():
                out.setdefault(t_ns, []).append((index, phase))
        return out

    def true_position(self, t_ns: int) -> NDArray[np.float64] | None:
        """True robot position (2,) at ``t_ns`` (the last pose at or before it), or None."""
        i = bisect.bisect_right(self.truth_times_ns, t_ns) - 1
        if i < 0:
            return None
        pos: NDArray[np.float64] = self.truth_poses[i, :2].copy()
        return pos


def read_plan(log: ProcessableLog) -> MovementPlan:
    """Read ``/robot/movement`` and ``/sim/ground_truth`` (small channels) in one pass."""
    plan = MovementPlan()
    times: list[int] = []
    poses: list[tuple[float, float, float]] = []
    for msg in log.messages([MOVEMENT_TOPIC, TRUTH_TOPIC]):
        doc = msg.decode()
        if msg.topic == MOVEMENT_TOPIC:
            phases = plan.keyframes.setdefault(int(doc["index"]), {})
            phases[str(doc["phase"])] = ns_from_stamp(doc["keyframe_timestamp"])
            plan.turns_rad[int(doc["index"])] = float(doc["turn_rad"])
        else:
            times.append(ns_from_stamp(doc["timestamp"]))
            poses.append((float(doc["x"]), float(doc["y"]), float(doc["heading"])))
    order = np.argsort(times, kind="stable")
    plan.truth_times_ns = [times[i] for i in order]
    plan.truth_poses = np.array(poses, np.float64).reshape(-1, 3)[order]
    return plan
