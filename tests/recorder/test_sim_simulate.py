"""The library entry point of a simulated session (what simulate, demo and experiments call)."""

from __future__ import annotations

from pathlib import Path

from recorder.record import RecordSettings
from recorder.sim.scenario import builtin_scenario, scenario_from_dict
from recorder.sim.simulate import SimSettings, simulate_to_file
from tests.mcap_reader import LogReader


def test_simulate_to_file_writes_a_complete_log(tmp_path: Path) -> None:
    doc = builtin_scenario("paper").to_dict()
    doc["trajectory"] = {
        "start": [0.52, 0.34],
        "moves": [{"turn_deg": 90, "distance": 0.12}, {"turn_deg": -45, "distance": 0.1}],
    }
    scenario = scenario_from_dict(doc)
    seen: list[int] = []
    out = tmp_path / "s.mcap"
    result = simulate_to_file(
        scenario,
        out,
        settings=SimSettings(RecordSettings(frame_rate_hz=2.0, encoding="bgr8"), turn_noise=0.0),
        progress=lambda p: seen.append(p.movements),
    )
    assert (result.movements, seen) == (2, [1, 2])
    reader = LogReader(out)
    assert reader.finished
    session = reader.session()
    assert session.simulated and session.doc["camera"]["encoding"] == "bgr8"
    counts: dict[str, int] = {}
    for m in reader.messages():
        counts[m.topic] = counts.get(m.topic, 0) + 1
    assert counts["/robot/movement"] == 4
    assert counts["/camera/panorama"] == result.frames == counts["/sim/ground_truth"]
