"""Ground truth of simulated logs, expressed in the landmark frame FL for comparison.

The simulator knows landmark positions and robot poses in the ``world`` frame (metres). The map
is only defined up to a similarity, so truth is compared in FL: the similarity that sends the
reference pair L1 -> (0, 0) and L2 -> (1, 0) (unit |L1 L2|). Errors in FL units times the true
|L1 L2| are metres.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from data_schemas.session import Session
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


def class_of_name(name: str) -> str | None:
    """The class label of a landmark named by association (``"red#2"`` -> ``"red"``), else None."""
    label, sep, number = name.rpartition("#")
    return label if sep and label and number.isdigit() else None


def match_truth(
    truth: Truth, means_fl: Mapping[str, NDArray[np.floating]], classes: Mapping[str, Sequence[str]]
) -> dict[str, str]:
    """Which true landmark each estimate is: catalog names are themselves; a landmark named by
    association (``red#k``) is matched to the nearest true landmark of its class, one-to-one
    over the class (least total distance, scipy's ``linear_sum_assignment``).

    ``classes`` maps each shared class label to its catalog names. Estimates that match nothing
    (a class with no true landmark) are left out.
    """
    out = {n: n for n in means_fl if n in truth.landmarks_world}
    fl = truth.landmarks_fl()
    by_class: dict[str, list[str]] = {}
    for n in means_fl:
        label = class_of_name(n)
        if n not in out and label is not None and label in classes:
            by_class.setdefault(label, []).append(n)
    for label, names in by_class.items():
        trues = [t for t in classes[label] if t in fl]
        if not trues:
            continue
        cost = np.array(
            [[float(np.hypot(*(np.asarray(means_fl[n]) - fl[t]))) for t in trues] for n in names]
        )
        from scipy.optimize import linear_sum_assignment  # about 0.6 s: only when needed

        rows, cols = linear_sum_assignment(cost)
        out.update({names[r]: trues[c] for r, c in zip(rows, cols, strict=True)})
    return out


def errors_m(
    truth: Truth, means_fl: Mapping[str, NDArray[np.floating]], classes: Mapping[str, Sequence[str]]
) -> dict[str, float]:
    """Error (m) of each estimate against the true landmark :func:`match_truth` gives it."""
    matched = match_truth(truth, means_fl, classes)
    return {n: truth.error_m(t, means_fl[n]) for n, t in matched.items()}


def truth_from_scenario(scenario: dict[str, object], reference: tuple[str, str]) -> Truth:
    """Read landmark positions from a scenario document (see ``bslam.Scenario``)."""
    entries = scenario["landmarks"]
    assert isinstance(entries, list)
    landmarks = {str(e["name"]): np.array([e["x"], e["y"]], np.float64) for e in entries}
    return Truth(landmarks, WorldToFL(landmarks[reference[0]], landmarks[reference[1]]))


def truth_of_session(session: Session) -> Truth | None:
    """The truth a log's session holds: a simulated scenario's landmarks, or the landmark
    positions an imported session's outside reference measured (evaluation only); else None."""
    if session.scenario:
        return truth_from_scenario(session.scenario, session.reference)
    measured = session.truth_landmarks_m()
    if not measured or not all(r in measured for r in session.reference):
        return None
    landmarks = {n: np.array(p, np.float64) for n, p in measured.items()}
    l1, l2 = session.reference
    return Truth(landmarks, WorldToFL(landmarks[l1], landmarks[l2]))
