"""Calibration of the joint map per arena family, on real simulated logs (images, bearing
extraction, the joint estimator): the 80% regions hold the truth about 80% of the time in every
family (replay/experiments/families.py), fixed seeds, about 100 regions per family.

The band is two binomial standard deviations of a share of 0.8 at the family's number of
regions (about +-0.08 at 100): a family whose regions are about as calibrated as the goal asks
(75-85%; docs/RESULTS.md measures each family on 300-900 regions of fresh seeds with `bslam
experiment calibration`: 76-85% on seeds 14000 and up; on 15000 and up every family but the
random arenas, 72%, which read 77% over four fresh sets) passes, one whose regions hold the
truth two thirds of the time or 95% of the time does not.
Regions of one run share its keyframes, so a set of 40 regions from 20 runs strays by more than
its binomial std (the random family read 66% on 38 regions, 74% on 88, 80% on 177). And no
landmark confidently wrong: the truth within each landmark's 99.99% region.

The families are split over two classes so that two test workers share them (pytest-xdist
gives each class its own worker).
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from replay.experiments.calibration import LandmarkScore, coverage, score_run
from replay.experiments.families import FAMILIES

#: Runs per family, about 100 regions each: the paper's arena and the wide sparse one score
#: two landmarks a run, the random ones about three, the corridor four, close pairs and coded six.
SEEDS = {
    "paper": range(50),
    "paper_noise_free": range(50),
    "noise_free": range(34),
    "varied": range(34),
    "long": range(25),
    "close_pairs": range(17),
    "coded": range(17),
    "wide_sparse": range(50),
}


@functools.cache
def _scores(family: str) -> list[LandmarkScore]:
    return [s for seed in SEEDS[family] for s in score_run(family, seed)]


def test_every_family_is_measured_once() -> None:
    split = [*TestSmallArenas.families, *TestLargeArenas.families]
    assert sorted(split) == sorted(SEEDS) == sorted(FAMILIES)


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    if "family" in metafunc.fixturenames and metafunc.cls is not None:
        metafunc.parametrize("family", metafunc.cls.families)


#: Landmarks known to lie beyond their 99.99% region on these seeds (a strict expected failure
#: each): family -> (seed, name, squared Mahalanobis distance, error cm, batch least squares cm).
#: Batch least squares on the same bearings is as far off each time: the bearings point there.
#: The paper's arena: chi2(2) puts 4e-5 beyond d^2 20, one such among 100 regions is a tail
#: event or a detection error. No added noise: the extraction's errors are heavier-tailed than
#: a Gaussian (docs/RESULTS.md: 5 of 296 fresh regions beyond 99.99%).
CONFIDENTLY_WRONG = {
    "paper": (28, "L4", 20.1, 3.93, 4.01),
    "noise_free": (26, "L3", 36.1, 2.66, 2.67),
}


class _Calibration:
    families: tuple[str, ...] = ()

    @pytest.mark.slow
    def test_80_percent_regions_hold_the_truth_80_percent_of_the_time(self, family: str) -> None:
        scores = _scores(family)
        n = len(scores)
        assert n >= 90
        band = 2.0 * math.sqrt(0.8 * 0.2 / n)
        assert abs(coverage(scores) - 0.8) <= band, (coverage(scores), n)
        assert np.all(np.isfinite([s.error_cm for s in scores]))

    @pytest.mark.slow
    def test_no_landmark_is_confidently_wrong(
        self, family: str, request: pytest.FixtureRequest
    ) -> None:
        if family in CONFIDENTLY_WRONG:
            why = f"known: seed, name, d^2, error cm, LS cm = {CONFIDENTLY_WRONG[family]}"
            request.applymarker(pytest.mark.xfail(strict=True, reason=why))
        # the truth within the 99.99% region of every landmark (chi2(2) 18.4)
        worst = max(_scores(family), key=lambda s: s.d2)
        assert worst.d2 <= -2.0 * math.log(1e-4), worst


class TestSmallArenas(_Calibration):
    """The paper's arena and the random arenas."""

    families = ("paper", "paper_noise_free", "noise_free", "varied")


class TestLargeArenas(_Calibration):
    """The corridor, close pairs, coded and wide sparse arenas."""

    families = ("long", "close_pairs", "coded", "wide_sparse")
