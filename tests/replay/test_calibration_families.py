"""Calibration of the joint map per arena family, on real simulated logs (images, bearing
extraction, the joint estimator): the 80% regions hold the truth about 80% of the time in every
family (replay/experiments/families.py), fixed seeds, at least 40 regions per family.

The band is two binomial standard deviations of a share of 0.8 at the family's number of
regions (about +-0.13 at 40): a family whose regions are as calibrated as the goal asks
(75-85%, measured over more seeds in docs/RESULTS.md) passes, one whose regions hold the truth
two thirds of the time or 95% of the time does not. And no landmark confidently wrong: the truth
within each landmark's 99.99% region.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from replay.experiments.calibration import LandmarkScore, coverage, score_run
from replay.experiments.families import FAMILIES

#: Runs per family: at least 40 regions (the paper's arena scores two landmarks a run).
SEEDS = {
    "paper": range(20),
    "paper_noise_free": range(20),
    "noise_free": range(16),
    "long": range(10),
    "close_pairs": range(7),
    "coded": range(7),
    "wide_sparse": range(20),
    # 3 regions a run: seeds 0-13 alone read 66% of 38 (regions of one run are not
    # independent), 0-29 74% of 88; 60 fresh runs 80% (docs/RESULTS.md)
    "varied": range(30),
}


@functools.cache
def _scores(family: str) -> list[LandmarkScore]:
    return [s for seed in SEEDS[family] for s in score_run(family, seed)]


def test_every_family_is_measured() -> None:
    assert set(SEEDS) == set(FAMILIES)


@pytest.mark.slow
@pytest.mark.parametrize("family", FAMILIES)
def test_80_percent_regions_hold_the_truth_80_percent_of_the_time(family: str) -> None:
    scores = _scores(family)
    n = len(scores)
    assert n >= 40
    band = 2.0 * math.sqrt(0.8 * 0.2 / n)
    assert abs(coverage(scores) - 0.8) <= band, (coverage(scores), n)
    assert np.all(np.isfinite([s.error_cm for s in scores]))


#: Families with a known confidently wrong landmark on these seeds (open: issue 32's note).
#: close_pairs seed 5: L8 (coded, 6-10 cm from L7) ends 1.65 m off with a region that puts the
#: truth at a squared Mahalanobis distance of about 29,000; batch least squares on the same
#: bearings is 1.40 m off, so its bearings themselves point elsewhere (a wrong detection the map
#: trusts).
CONFIDENTLY_WRONG = {"close_pairs"}


@pytest.mark.slow
@pytest.mark.parametrize(
    "family",
    [
        pytest.param(f, marks=pytest.mark.xfail(strict=True, reason="a confidently wrong landmark"))
        if f in CONFIDENTLY_WRONG
        else f
        for f in FAMILIES
    ],
)
def test_no_landmark_is_confidently_wrong(family: str) -> None:
    # the truth within the 99.99% region of every landmark (chi2(2) 18.4)
    d2 = sorted(s.d2 for s in _scores(family))
    assert d2[-1] <= -2.0 * math.log(1e-4), d2[-3:]
