"""Ground truth of a simulated scenario in the landmark frame FL, and its description in cm.

FL sends the reference pair to L1 = (0, 0), L2 = (1, 0): with points as complex numbers,
``z_fl = (z_world - L1) / (L2 - L1)`` (a similarity transform), and one FL unit is |L1 L2|.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray


def landmarks_world(scenario: dict[str, Any]) -> dict[str, NDArray[np.float64]]:
    """Landmark name -> true position (x, y) in metres, world frame."""
    return {
        lm["name"]: np.array([lm["x"], lm["y"]], dtype=np.float64) for lm in scenario["landmarks"]
    }


def baseline_m(scenario: dict[str, Any]) -> float:
    """True |L1 L2| in metres (the FL unit)."""
    world = landmarks_world(scenario)
    l1, l2 = (world[n] for n in scenario["reference"])
    return float(np.hypot(*(l2 - l1)))


def world_to_fl(points_world: NDArray[np.float64], scenario: dict[str, Any]) -> NDArray[np.float64]:
    """Map points (..., 2) in metres, world frame, to FL (unit |L1 L2|)."""
    world = landmarks_world(scenario)
    l1, l2 = (complex(*world[n]) for n in scenario["reference"])
    z = (points_world[..., 0] + 1j * points_world[..., 1] - l1) / (l2 - l1)
    return np.stack([z.real, z.imag], axis=-1)


def truth_fl(scenario: dict[str, Any]) -> dict[str, NDArray[np.float64]]:
    """Landmark name -> true position in FL."""
    return {name: world_to_fl(p, scenario) for name, p in landmarks_world(scenario).items()}


def scored_landmarks(scenario: dict[str, Any]) -> list[str]:
    """The landmarks whose error is measured: every one but the reference pair."""
    return [lm["name"] for lm in scenario["landmarks"] if lm["name"] not in scenario["reference"]]


def describe(scenario: dict[str, Any]) -> dict[str, Any]:
    """The geometry for the report: arena, baseline and landmarks in cm, camera, noise."""
    traj = scenario["trajectory"]
    length = traj.get("distance")
    return {
        "arena_cm": [100.0 * scenario["arena"]["width"], 100.0 * scenario["arena"]["height"]],
        "baseline_cm": 100.0 * baseline_m(scenario),
        "landmarks_cm": {
            n: (100.0 * p).round(1).tolist() for n, p in landmarks_world(scenario).items()
        },
        "camera": f"{scenario['camera']['model']} {scenario['camera']['width']}x"
        f"{scenario['camera']['height']}",
        "bearing_noise_deg": scenario["camera"].get("bearing_noise_deg"),
        "vision_error_deg": scenario["vision_error_deg"],
        "movement_length": "as scenario"
        if length is None
        else f"{100 * length[0]:.0f}-{100 * length[1]:.0f} cm",
    }
