"""A name whose detections with the final map do not meet at one point is flagged
(:func:`pipeline.association.support.misfit`): rays built by hand from one landmark, or from
two landmarks 12 cm apart, with Gaussian bearing noise of known std; the level is the
chi-square law's (an outside oracle: the noise is drawn here, its law is known)."""

from __future__ import annotations

import math

import numpy as np

from pipeline.association.final import FinalDetection, Status, weak_names
from pipeline.association.support import MISFIT_RUN_RISK, misfit
from pipeline.estimate import LandmarkEstimate
from pipeline.geometry import KeyframePose

DEG = math.pi / 180.0
NOISE = 1.0 * DEG
A = np.array([0.0, 0.0])
B = np.array([0.0, 0.12])  # 12 cm from A: 5-7 degrees apart from 1-1.4 m


def _rays(rng: np.random.Generator, n: int, second: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """n keyframes on an arc 1-1.4 m from A over 120 degrees; ``second`` of them, drawn at
    random, see B instead of A; bearing noise NOISE (directions in FL)."""
    ang = np.linspace(-60.0, 60.0, n) * DEG
    origins = np.column_stack((np.cos(ang), np.sin(ang))) * rng.uniform(1.0, 1.4, n)[:, None]
    seen = np.tile(A, (n, 1))
    seen[rng.choice(n, second, replace=False)] = B
    d = seen - origins
    return origins, np.arctan2(d[:, 1], d[:, 0]) + rng.normal(0.0, NOISE, n)


def test_one_landmark_s_rays_are_flagged_at_the_stated_rate_only() -> None:
    rng = np.random.default_rng(7)
    trials, n = 2000, 20
    flagged = 0
    for _ in range(trials):
        origins, dirs = _rays(rng, n)
        flagged += misfit(origins, dirs, np.full(n, NOISE**2), A + 0.01, names=1) is not None
    # 1 % per name alone: about 20 of 2000 (binomial std 4.5)
    assert 8 <= flagged <= 35, flagged
    # among 16 names tested together each at 1 - 1 % / 16: about 1.25 of 2000 expected
    rng = np.random.default_rng(8)
    together = 0
    for _ in range(trials):
        origins, dirs = _rays(rng, n)
        together += misfit(origins, dirs, np.full(n, NOISE**2), A, names=16) is not None
    assert together <= 6, together
    assert MISFIT_RUN_RISK == 0.01


def test_rays_of_two_landmarks_mixed_are_flagged() -> None:
    rng = np.random.default_rng(9)
    for second in (12, 6):
        for _ in range(200):
            origins, dirs = _rays(rng, 24, second)
            why = misfit(origins, dirs, np.full(24, NOISE**2), A, names=16)
            # half, or a quarter, of 24 rays seeing B 5-7 degrees from A: whatever point fits
            # them, the residuals' squares sum far beyond chi-square(22) at 1 - 1 % / 16
            assert why is not None and "do not meet at one point" in why


def test_too_few_rays_are_not_judged() -> None:
    origins = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]])
    dirs = np.array([math.pi, -math.pi / 2, 0.3])  # the third misses A by 17 degrees
    assert misfit(origins, dirs, np.full(3, NOISE**2), A, names=1) is None


def test_the_final_map_s_weak_names_include_one_whose_detections_do_not_meet() -> None:
    # blue#1 at A, given the detections of 24 keyframes of which 8 see B: every keyframe
    # predicts it sharply and gives it a detection (not weak by share), yet they do not meet
    # at one point
    rng = np.random.default_rng(3)
    origins, dirs = _rays(rng, 24, 8)
    sharp = 1e-8 * np.eye(3)
    poses = {(k, 0): KeyframePose(origins[k], 0.0, sharp) for k in range(24)}
    final = [
        FinalDetection(k, 0, "blue", float(dirs[k]), "blue#1", Status.NAMED) for k in range(24)
    ]
    mapped = {"blue#1": LandmarkEstimate(A.copy(), 1e-6 * np.eye(2))}
    weak = weak_names(final, poses, mapped, ["blue#1"], noise_rad=NOISE, eps_rad=3 * DEG)
    assert list(weak) == ["blue#1"] and "do not meet at one point" in weak["blue#1"]
    # the same keyframes seeing A only: not weak
    rng = np.random.default_rng(3)
    origins, dirs = _rays(rng, 24)
    final = [
        FinalDetection(k, 0, "blue", float(dirs[k]), "blue#1", Status.NAMED) for k in range(24)
    ]
    assert weak_names(final, poses, mapped, ["blue#1"], noise_rad=NOISE, eps_rad=3 * DEG) == {}
