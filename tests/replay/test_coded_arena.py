"""Issue 11's arena of 20 coded landmarks (3 x 2 m, unwrapped 960 x 160, bearing noise 1 deg,
eps 3 deg) through the real simulator and the default pipeline. The goal: every landmark mapped,
mean error <= 3 cm and worst <= 10 cm. Figures per seed, and the harder variants (10 movements,
the built-in 46 cm reference baseline), in docs/RESULTS.md.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from alike_scenarios import coded_wide_reference

from replay.experiments.run import simulate
from replay.records import MethodConfig
from replay.sinks.summary import SummarySink
from replay.stages import run_log


@pytest.mark.slow
def test_twenty_coded_landmarks_in_twenty_movements(tmp_path: Path) -> None:
    # a 1.18 m reference baseline and 20 movements: every landmark mapped in every run, and the
    # accuracy goal met in at least 9 of 10 (docs/RESULTS.md: 10 of 10 on these seeds, 9 of 10
    # on seeds 10-19, whose miss has its worst landmark 2 of its own std off)
    met = 0
    for seed in range(10):
        log = tmp_path / f"coded_{seed}.mcap"
        simulate(coded_wide_reference(moves=20), log, seed=seed)
        collect = SummarySink()
        run_log(log, MethodConfig(), [collect])
        errors_m = list(collect.document["error_m"].values())
        assert len(errors_m) == 18, seed  # every landmark beyond the reference pair
        met += sum(errors_m) / 18 <= 0.03 and max(errors_m) <= 0.10
    assert met >= 9, met
