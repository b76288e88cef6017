"""Keyframes chosen from odometry: every ``distance_m`` of path or ``turn_rad`` of turning.

Travel is counted along the odometry samples since the last keyframe: the path length (sum of
the distances between consecutive positions) and the turning (sum of the absolute heading
changes, wrapped). A sample becomes a keyframe when either reaches its threshold; the first
sample is always one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad
from data_schemas.errors import EstimationError

#: Default path length between keyframes (m).
KEYFRAME_DISTANCE_M = 0.3
#: Default turning between keyframes (rad): 20 deg.
KEYFRAME_TURN_RAD = math.radians(20.0)


@dataclass(frozen=True)
class KeyframeRule:
    """When odometry makes a keyframe.

    Attributes
    ----------
    distance_m : float
        Path length (m) since the last keyframe that makes a new one (> 0).
    turn_rad : float
        Turning (rad, summed absolute heading changes) that makes a new one (> 0).
    """

    distance_m: float = KEYFRAME_DISTANCE_M
    turn_rad: float = KEYFRAME_TURN_RAD

    def __post_init__(self) -> None:
        for what, v in (("distance", self.distance_m), ("turn", self.turn_rad)):
            if not (math.isfinite(v) and v > 0.0):
                raise EstimationError(f"keyframe {what} must be a finite number > 0, got {v}")


class KeyframeSelector:
    """Decides, sample by sample, which odometry poses are keyframes (see the module doc)."""

    def __init__(self, rule: KeyframeRule) -> None:
        self.rule = rule
        self._last: NDArray[np.float64] | None = None
        self.path_m = 0.0
        self.turn_rad = 0.0
        #: path (m) and turning (rad) from the keyframe before the last one to the last one
        self.segment: tuple[float, float] = (0.0, 0.0)

    def add(self, pose: NDArray[np.float64]) -> bool:
        """Whether odometry pose ``pose`` (3,) = x (m), y (m), theta (rad) is a keyframe."""
        last, self._last = self._last, np.asarray(pose, np.float64)
        if last is None:
            return True
        self.path_m += math.hypot(pose[0] - last[0], pose[1] - last[1])
        self.turn_rad += abs(float(wrap_rad(float(pose[2] - last[2]))))
        if self.path_m >= self.rule.distance_m or self.turn_rad >= self.rule.turn_rad:
            self.segment = (self.path_m, self.turn_rad)
            self.path_m = self.turn_rad = 0.0
            return True
        return False


def select_keyframes(poses: NDArray[np.float64], rule: KeyframeRule) -> NDArray[np.int64]:
    """Indices (k,) of the keyframes among odometry poses (n, 3) (m, m, rad), in order."""
    sel = KeyframeSelector(rule)
    return np.array([i for i, p in enumerate(np.asarray(poses)) if sel.add(p)], np.int64)
