"""The task runner: in process, local process pool, local Dask cluster; failures stay local."""

from __future__ import annotations

import pytest

from data_schemas.errors import LogError
from replay.parallel import Outcome, run_tasks


def square_or_fail(x: int) -> int:
    if x == 3:
        raise ValueError("three is bad\nsecond line")
    return x * x


def user_error(x: int) -> int:
    raise LogError(f"log {x} is not an MCAP file")


def test_user_errors_keep_their_own_message() -> None:
    (outcome,) = run_tasks(user_error, [7], progress=False)
    assert outcome.error == "log 7 is not an MCAP file"


@pytest.mark.parametrize("workers", [1, 2])
def test_pool_keeps_order_and_isolates_failures(workers: int) -> None:
    seen: list[Outcome[int]] = []
    outcomes = run_tasks(
        square_or_fail, list(range(6)), workers=workers, progress=False, on_outcome=seen.append
    )
    assert [o.index for o in outcomes] == list(range(6))
    assert sorted(seen, key=lambda o: o.index) == outcomes
    assert [o.value for o in outcomes if o.ok] == [0, 1, 4, 16, 25]
    bad = outcomes[3]
    assert not bad.ok and bad.value is None
    assert bad.error == "ValueError: three is bad"


def test_dask_local_cluster() -> None:
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None
    ) as cluster:
        outcomes = run_tasks(
            square_or_fail, list(range(5)), scheduler=cluster.scheduler_address, progress=False
        )
    assert [o.value for o in outcomes] == [0, 1, 4, None, 16]
    assert outcomes[3].error == "ValueError: three is bad"
