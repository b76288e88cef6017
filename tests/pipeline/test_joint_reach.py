"""A landmark out of every vision cone's reach (pipeline.joint.robustness.out_of_reach), on
hand-placed keyframes: the impartial prior holds a landmark only within r_max movement lengths
of the keyframe that saw it."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pipeline.joint.robustness import out_of_reach


def _arrays(*rows: tuple[float, float]) -> NDArray[np.float64]:
    return np.array(rows, np.float64)


def test_a_point_beyond_r_max_lengths_of_every_keyframe_is_out_of_reach() -> None:
    # two bearings, both from movements of length 1: ranges hypot(1, 21) = 21.02 and 21
    ends = _arrays((1.0, 0.0), (0.0, 0.0))
    starts = _arrays((0.0, 0.0), (1.0, 0.0))
    point = np.array([0.0, 21.0])
    assert out_of_reach(point, ends, starts, 20.0)
    assert not out_of_reach(point, ends, starts, 21.5)  # 21.02 and 21 within 21.5 lengths


def test_one_keyframe_within_reach_keeps_the_landmark_possible() -> None:
    # the second bearing's movement is 2 long: its reach is 40, the range 21
    ends = _arrays((1.0, 0.0), (2.0, 0.0))
    starts = _arrays((0.0, 0.0), (0.0, 0.0))
    point = np.array([0.0, 21.0])
    assert not out_of_reach(point, ends, starts, 20.0)


def test_reach_scales_with_the_movement_not_with_the_frame() -> None:
    # the same scene in a frame ten times larger: the verdict is the same
    ends = _arrays((10.0, 0.0), (0.0, 0.0))
    starts = _arrays((0.0, 0.0), (10.0, 0.0))
    point = np.array([0.0, 210.0])
    assert out_of_reach(point, ends, starts, 20.0)
    assert not out_of_reach(point / 2.0, ends, starts, 20.0)  # 105 within 200
