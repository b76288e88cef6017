"""The scenario's geometry as the experiment reports it: scored landmarks, sizes in cm.

Truth in FL comes from :func:`replay.truth.truth_from_scenario` (unit |L1 L2|).
"""

from __future__ import annotations

from typing import Any

from replay.truth import truth_from_scenario


def scored_landmarks(scenario: dict[str, Any]) -> list[str]:
    """The landmarks whose error is measured: every one but the reference pair."""
    return [lm["name"] for lm in scenario["landmarks"] if lm["name"] not in scenario["reference"]]


def describe(scenario: dict[str, Any]) -> dict[str, Any]:
    """The geometry for the report: arena, baseline and landmarks in cm, camera, noise."""
    truth = truth_from_scenario(scenario, tuple(scenario["reference"]))
    length = scenario["trajectory"].get("distance")
    return {
        "arena_cm": [100.0 * scenario["arena"]["width"], 100.0 * scenario["arena"]["height"]],
        "baseline_cm": 100.0 * truth.to_fl.unit_m,
        "landmarks_cm": {
            n: (100.0 * p).round(1).tolist() for n, p in truth.landmarks_world.items()
        },
        "camera": f"{scenario['camera']['model']} {scenario['camera']['width']}x"
        f"{scenario['camera']['height']}",
        "bearing_noise_deg": scenario["camera"].get("bearing_noise_deg", 0.0),
        "vision_error_deg": scenario["vision_error_deg"],
        "movement_length": "as listed"
        if length is None
        else f"{100 * length[0]:.0f}-{100 * length[1]:.0f} cm",
    }
