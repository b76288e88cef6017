"""The movements of a log: which frames are keyframes, and the simulator's true poses.

``/robot/movement`` has a ``start`` and an ``end`` message per straight movement; each points at
its keyframe through ``keyframe_timestamp``, equal to that frame's ``timestamp``. The recorder
writes ``/robot/odometry`` (encoder counters, reset before each motion) just before each movement
message, with the same ``timestamp``: at ``end`` it holds the wheel travel of the drive. The plan
grows message by message (:meth:`MovementPlan.add`), so a log can be followed while it is written.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from data_schemas.mcap.processable import ProcessableLog
from data_schemas.registry import MOVEMENT_TOPIC, ODOMETRY_TOPIC, SIM_TRUTH_TOPIC
from data_schemas.stamps import ns_from_stamp

PLAN_TOPICS = (MOVEMENT_TOPIC, ODOMETRY_TOPIC, SIM_TRUTH_TOPIC)
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
    truth_poses : list of (x, y, heading)
        Matching poses (m, m, rad; world frame).
    turns_rad : dict index -> float
        Commanded turn in place before each movement (CCW, rad).
    distances_m : dict index -> float
        Straight distance of each movement (m): the wheel travel of the odometry logged with its
        ``end`` message (mean of both wheels), else the commanded distance.
    """

    keyframes: dict[int, dict[str, int]] = field(default_factory=dict)
    turns_rad: dict[int, float] = field(default_factory=dict)
    distances_m: dict[int, float] = field(default_factory=dict)
    #: wheel travel (m) of the odometry messages not yet matched, by their time stamp (ns)
    _travel_m: dict[int, float] = field(default_factory=dict)
    truth_times_ns: list[int] = field(default_factory=list)
    truth_poses: list[tuple[float, float, float]] = field(default_factory=list)

    def add(self, topic: str, doc: dict[str, Any]) -> tuple[int, str, int] | None:
        """Take one message of :data:`PLAN_TOPICS` (decoded).

        Returns
        -------
        (index, phase, keyframe_ns) or None
            For a movement message: the movement, its phase and its keyframe's time stamp.
        """
        if topic == MOVEMENT_TOPIC:
            index, phase = int(doc["index"]), str(doc["phase"])
            t_ns = self.keyframes.setdefault(index, {})[phase] = ns_from_stamp(
                doc["keyframe_timestamp"]
            )
            self.turns_rad[index] = float(doc["turn_rad"])
            travel = self._travel_m.pop(ns_from_stamp(doc["timestamp"]), None)
            if phase == "end" and travel is not None:
                self.distances_m[index] = travel
            elif index not in self.distances_m:
                self.distances_m[index] = float(doc["distance_m"])
            return index, phase, t_ns
        if topic == ODOMETRY_TOPIC:
            mm = doc.get("mm_per_pulse")
            if mm is not None:
                pulses = 0.5 * (float(doc["left_pulses"]) + float(doc["right_pulses"]))
                self._travel_m[ns_from_stamp(doc["timestamp"])] = abs(pulses) * float(mm) / 1e3
            return None
        if topic == SIM_TRUTH_TOPIC:
            t_ns = ns_from_stamp(doc["timestamp"])
            i = bisect.bisect_right(self.truth_times_ns, t_ns)
            self.truth_times_ns.insert(i, t_ns)
            self.truth_poses.insert(i, (float(doc["x"]), float(doc["y"]), float(doc["heading"])))
        return None

    def true_position(self, t_ns: int) -> NDArray[np.float64] | None:
        """True robot position (2,) at ``t_ns`` (the last pose at or before it), or None."""
        i = bisect.bisect_right(self.truth_times_ns, t_ns) - 1
        if i < 0:
            return None
        return np.array(self.truth_poses[i][:2], np.float64)


def read_plan(log: ProcessableLog) -> MovementPlan:
    """Read ``/robot/movement``, ``/robot/odometry`` and ``/sim/ground_truth`` (small channels)
    in one pass."""
    plan = MovementPlan()
    for msg in log.messages(PLAN_TOPICS):
        plan.add(msg.topic, msg.decode())
    return plan
