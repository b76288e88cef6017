"""The joint map's unit in metres, estimated from the driven distances, in the summary."""

from __future__ import annotations

from pathlib import Path

import pytest

from replay.records import MethodConfig
from replay.sinks.summary import SummarySink
from replay.stages import run_log

REGRESS = Path(__file__).parents[1] / "data" / "regress"


def _summary(name: str, method: MethodConfig) -> dict[str, object]:
    sink = SummarySink()
    run_log(REGRESS / f"{name}.mcap", method, [sink])
    return sink.document


@pytest.mark.parametrize("name", ["unwrapped", "occluded"])
def test_map_unit_is_the_true_reference_distance(name: str) -> None:
    doc = _summary(name, MethodConfig())
    truth_m = doc["truth"]["unit_m"]  # type: ignore[index]
    # simulated driven distances carry 2 % noise per movement; the map's scale comes from all
    assert abs(doc["map_unit_m"] - truth_m) <= 0.05 * truth_m  # type: ignore[operator]
    per_movement = [m["map_unit_m"] for m in doc["movements"] if "map_unit_m" in m]  # type: ignore[attr-defined]
    assert per_movement and per_movement[-1] == doc["map_unit_m"]


def test_no_map_unit_without_the_distance_prior() -> None:
    doc = _summary("unwrapped", MethodConfig(distance_prior=None))
    assert "map_unit_m" not in doc
    assert all("map_unit_m" not in m for m in doc["movements"])  # type: ignore[attr-defined]
