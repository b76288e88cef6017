"""Following a log: the same result as offline processing, on stored and fresh logs."""

from __future__ import annotations

from pathlib import Path

import pytest

from replay.follow import FollowedLog
from replay.logs import ProcessableLog
from replay.process import process_log
from replay.records import MethodConfig
from replay.sinks.summary import SummarySink

REGRESS = Path(__file__).resolve().parents[1] / "data" / "regress"
METHOD = MethodConfig(n_l=150, seed=7)


@pytest.mark.parametrize("name", ["unwrapped", "omni", "degenerate", "occluded"])
def test_followed_finished_log_gives_the_offline_result(name: str) -> None:
    path = REGRESS / f"{name}.mcap"
    with ProcessableLog(path) as log:
        offline = process_log(log, METHOD)
    with FollowedLog(path, idle_timeout_s=2) as log:
        followed = process_log(log, METHOD)
        assert log.end == "finished"
    assert followed == offline
    assert any(m["status"] == "ok" for m in offline["movements"])


def test_followed_hand_made_log_gives_the_offline_result(small_log: Path) -> None:
    # every frame (the Rerun sink's view): frames between keyframes are decoded too
    class AllFrames(SummarySink):
        wants_all_frames = True

    docs = []
    for opener in (ProcessableLog, lambda p: FollowedLog(p, idle_timeout_s=2)):
        sink = AllFrames()
        with opener(small_log) as log:
            process_log(log, METHOD, extra_sinks=(sink,))
        docs.append(sink.document)
    assert docs[0] == docs[1]
