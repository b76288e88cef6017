"""Never silently wrong, per name: on simulated runs of many identical landmarks whose maps
put names more than 10 cm from their landmarks (the truth measured directly), the result line
names every one of them among the reasons the map is not trustworthy; and a clean map's right
names are not flagged."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from alike_scenarios import alike_arena
from alike_scoring import score_log
from click.testing import CliRunner

from replay.cli import cli
from replay.experiments.run import simulate
from replay.process import result_line


def _flagged(reasons: list[str]) -> set[str]:
    return {name for r in reasons for name in (w.strip(",()") for w in r.split()) if "#" in name}


@pytest.mark.slow  # simulated 30-movement runs, 10-30 s each
@pytest.mark.parametrize(
    ("n", "size_m", "camera", "seed", "off_before"),
    [
        # final maps that still put a name 1.2-1.8 m off (flagged before too)
        (12, (4.0, 3.0), "omni", 1, True),
        (16, (5.0, 4.0), "unwrapped", 1, True),
        # blue#12 11.4 cm off, its 99 % region reaching 9.98 cm: within 10 cm for one name,
        # not for the run's 12 names together
        (12, (4.0, 3.0), "omni", 9, True),
        # blue#12 and blue#15 17-20 cm off, weak with the final map (16 unwrapped seed 19, its
        # name 18.5 cm off, is mended by the map built again from the first movement)
        (16, (5.0, 4.0), "unwrapped", 7, True),
        # the summary held the last movement's map, blue#10 16.5 cm off; the final map (after
        # association and map were made to agree) has it 1.7 cm off
        (12, (4.0, 3.0), "unwrapped", 20, False),
    ],
    ids=["12-omni-1", "16-unwrapped-1", "12-omni-9", "16-unwrapped-7", "12-unwrapped-20"],
)
def test_every_name_more_than_10_cm_off_is_flagged_by_name(
    n: int,
    size_m: tuple[float, float],
    camera: str,
    seed: int,
    off_before: bool,
    tmp_path: Path,
) -> None:
    log = tmp_path / "run.mcap"
    simulate(alike_arena(n, camera, size_m, seed=seed), log, seed=seed)
    s = score_log(log)
    off = {name for name, e in s.errors_m.items() if e > 0.10}
    if off_before:
        assert off  # these layouts still put names off: else the test tests nothing
    trust = s.summary["trust"]
    flagged = _flagged(trust.get("reasons", []))
    assert off <= flagged, (off - flagged, trust)
    line = result_line(s.result)
    assert all(name in line for name in off)
    if off:
        assert not trust["trustworthy"] and "NOT trustworthy" in line


@pytest.mark.slow  # one simulated 30-movement run, about 10 s
def test_a_clean_map_s_right_names_are_not_flagged(tmp_path: Path) -> None:
    # 12 identical landmarks, unwrapped camera, seed 12: every name within 10 cm of its
    # landmark (measured against the truth); the tests of a name's detections and of its
    # region, taken for the run's 12 names together, flag none of them
    log = tmp_path / "run.mcap"
    simulate(alike_arena(12, "unwrapped", (4.0, 3.0), seed=12), log, seed=12)
    s = score_log(log)
    assert len(s.errors_m) == 12 and max(s.errors_m.values()) <= 0.10
    assert s.summary["trust"] == {"trustworthy": True}
    assert "NOT trustworthy" not in result_line(s.result)


@pytest.mark.slow  # one simulated 30-movement run, about 15 s
def test_an_untrustworthy_map_is_a_result_bslam_process_exits_0(tmp_path: Path) -> None:
    # 12 identical landmarks, omni camera, seed 9: blue#12 ends 11.4 cm off (truth measured)
    log, summary = tmp_path / "run.mcap", tmp_path / "run.summary.json"
    simulate(alike_arena(12, "omni", (4.0, 3.0), seed=9), log, seed=9)
    result = CliRunner().invoke(cli, ["process", str(log), "--summary", str(summary)])
    assert result.exit_code == 0, result.output
    doc = json.loads(summary.read_text())
    assert doc["error_m"]["blue#12"] > 0.10
    assert doc["trust"]["trustworthy"] is False
    assert "blue#12" in _flagged(doc["trust"]["reasons"])
    assert "the map is NOT trustworthy" in result.output and "blue#12" in result.output
