"""Ground truth of simulated logs, expressed in the landmark frame FL for comparison.

The simulator knows landmark positions and robot poses in the ``world`` frame (metres). The map
is only defined up to a similarity, so truth is compared in FL: the similarity that sends the
reference pair L1 -> (0, 0) and L2 -> (1, 0) (unit |L1 L2|). Errors in FL units times the true
|L1 L2| are metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pipeline.frame_change import to_fl


@dataclass(frozen=True)
class WorldToFL:
    """The similarity world -> FL fixed by the reference pair's true positions.

    Attributes
    ----------
    l1_world, l2_world : (2,) float arrays
        True positions of the reference pair, metres, world frame.
    """

    l1_world: NDArray[np.float64]
    l2_world: NDArray[np.float64]

    @property
    def unit_m(self) -> float:
        """Length of the FL unit |L1 L2| in metres."""
        return float(np.hypot(*(self.l2_world - self.l1_world)))

    def apply(self, points_world: NDArray[np.floating]) -> NDArray[np.float64]:
        """Map points (..., 2) in metres, world frame, to FL (..., 2)."""
        return to_fl(np.asarray(points_world, np.float64), self.l1_world, self.l2_world)


@dataclass(frozen=True)
class Truth:
    """What a simulated session knows for sure.

    Attributes
    ----------
    landmarks_world : dict name -> (2,) array
        Landmark positions, metres, world frame.
    to_fl : WorldToFL
        The world -> FL similarity of the session's reference pair.
    """

    landmarks_world: dict[str, NDArray[np.float64]]
    to_fl: WorldToFL

    def landmarks_fl(self) -> dict[str, NDArray[np.float64]]:
        """Landmark positions in FL (the reference pair lands on (0, 0) and (1, 0))."""
        return {name: self.to_fl.apply(p) for name, p in self.landmarks_world.items()}

    def error_m(self, name: str, mean_fl: NDArray[np.floating]) -> float:
        """Distance (metres) between an FL estimate of ``name`` and its true position."""
        diff = np.asarray(mean_fl, np.float64) - self.to_fl.apply(self.landmarks_world[name])
        return float(np.hypot(*diff)) * self.to_fl.unit_m


def truth_from_scenario(scenario: dict[str, object], reference: tuple[str, str]) -> Truth:
    """Read landmark positions from a scenario document (see ``bslam.Scenario``)."""
    entries = scenario["landmarks"]
    assert isinstance(entries, list)
    landmarks = {str(e["name"]): np.array([e["x"], e["y"]], np.float64) for e in entries}
    return Truth(landmarks, WorldToFL(landmarks[reference[0]], landmarks[reference[1]]))
