"""Association over synthetic bearings (no images): ``n`` identical landmarks of class
``blue`` and a distinct reference pair, the joint estimator, the truth of every detection."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from pipeline.association import Associator, MovementAssociation
from pipeline.association.final import FinalDetection
from pipeline.estimators import make_estimator
from pipeline.fusion import PAPER_N_L, PAPER_N_R
from pipeline.joint.window import DEFAULT_WINDOW
from pipeline.slam import MovementObservation
from pipeline.synthetic import simulate_bearings
from recorder.sim.world import Arena, Landmark, SimWorld

EPS = math.radians(3.0)
ARENA_M = (1.6, 1.2)
REFERENCE_M = ((0.55, 0.6), (1.05, 0.6))
#: hide(movement, end, landmark) -> True drops that landmark's blob (a blue one or one of the
#: reference pair) from the keyframe
Hide = Callable[[int, int, str], bool]


@dataclass
class SyntheticRun:
    """What association did on one synthetic run, with the truth to score it."""

    associator: Associator
    results: list[MovementAssociation] = field(default_factory=list)
    given: list[tuple[int, int, str, str]] = field(default_factory=list)  # move, end, name, true
    #: per keyframe (movement, end), the landmarks hidden behind a nearer post
    occluded_at: dict[tuple[int, int], set[str]] = field(default_factory=dict)
    estimates_fl: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    truth_fl: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    unit_m: float = 1.0
    seconds: float = 0.0
    association_seconds: float = 0.0
    #: CPU seconds of each movement (association, estimator and their exchange)
    movement_cpu_seconds: list[float] = field(default_factory=list)
    #: every keyframe detection associated with the final map, and the landmark it truly is
    final: list[tuple[FinalDetection, str]] = field(default_factory=list)
    final_seconds: float = 0.0
    #: one search of the final map's repair (free names, retraction, names given anew)
    repair_seconds: float = 0.0

    def matched(self) -> dict[str, str]:
        """``blue#k`` -> true landmark: nearest, one-to-one."""
        names = sorted(self.estimates_fl)
        trues = sorted(t for t in self.truth_fl if t.startswith("B"))
        if not names:
            return {}
        cost = np.array(
            [
                [float(np.hypot(*(self.estimates_fl[n] - self.truth_fl[t]))) for t in trues]
                for n in names
            ]
        )
        from scipy.optimize import linear_sum_assignment  # ~0.5 s: not at collection

        rows, cols = linear_sum_assignment(cost)
        return {names[r]: trues[c] for r, c in zip(rows, cols, strict=True)}

    def errors_m(self) -> dict[str, float]:
        return {
            n: float(np.hypot(*(self.estimates_fl[n] - self.truth_fl[t]))) * self.unit_m
            for n, t in self.matched().items()
        }

    def correct_share(self) -> float:
        m = self.matched()
        ok = sum(1 for *_, name, true in self.given if m.get(name) == true)
        return ok / max(len(self.given), 1)


def layout(
    n: int, rng: np.random.Generator, spacing_m: float = 0.15
) -> dict[str, tuple[float, float]]:
    """The reference pair and ``n`` points at least ``spacing_m`` apart in the arena."""
    lms = {"L1": REFERENCE_M[0], "L2": REFERENCE_M[1]}
    while len(lms) < n + 2:
        p = (float(rng.uniform(0.1, ARENA_M[0] - 0.1)), float(rng.uniform(0.1, ARENA_M[1] - 0.1)))
        if all(math.dist(p, q) >= spacing_m for q in lms.values()):
            lms[f"B{len(lms) - 1}"] = p
    return lms


def run_synthetic(
    n: int,
    seed: int,
    *,
    moves: int = 20,
    capacity: int | None = None,
    hide: Hide | None = None,
    post_radius_m: float = 0.0,
    view_rad: tuple[float, float] | None = None,
    tell_view: bool = True,
) -> SyntheticRun:
    """``moves`` movements; the catalog says ``capacity`` (default ``n``) blue landmarks.
    With ``post_radius_m`` the landmarks are posts of that radius, and a post partly hidden
    behind a nearer one (the simulator's geometry, ``SimWorld.occluded_fractions``) has no
    blob: the nearer one's blob stands for both. With ``view_rad = (lo, hi)`` (within
    (-pi, pi)) the blue landmarks are seen only between those bearings (a narrow camera; the
    reference pair stays in view), and the associator is told so if ``tell_view``."""
    import time

    rng = np.random.default_rng(seed)
    lms = layout(n, rng)
    sim = simulate_bearings(
        moves, rng, landmarks_world=lms, arena_m=ARENA_M, move_m=(0.2, 0.4), clearance_m=0.08
    )
    assoc = Associator(
        {"blue": capacity or n},
        ("L1", "L2"),
        vision_error_rad=EPS,
        field_of_view_rad=view_rad if tell_view else None,
    )
    slam = make_estimator(
        "joint",
        ["L1", "L2", *assoc.names],
        ("L1", "L2"),
        vision_error_rad=EPS,
        rng=rng,
        prior="impartial",
        n_r=PAPER_N_R,
        n_l=PAPER_N_L,
        turn_prior_sigma_rad=None,
        distance_prior_rel=None,
        window=DEFAULT_WINDOW,
    )
    out = SyntheticRun(assoc, truth_fl=sim.truth_fl(("L1", "L2")), unit_m=math.dist(*REFERENCE_M))
    posts = None
    if post_radius_m > 0.0:
        posts = SimWorld(
            Arena(*ARENA_M),
            tuple(Landmark(k, x, y, "blue", post_radius_m) for k, (x, y) in lms.items()),
        )
    keyframe_blobs: dict[tuple[int, int], dict[str, list[float]]] = {}
    true_of: dict[tuple[int, int], list[str]] = {}  # the landmark of each blob
    tick = time.perf_counter()
    for obs in sim.observations:
        ends = (obs.bearings_o1_rad, obs.bearings_o2_rad)
        if posts is not None:
            behind = []
            for e, origin in enumerate((sim.o1_world[obs.index], sim.o2_world[obs.index])):
                hidden = posts.occluded_fractions((float(origin[0]), float(origin[1]), 0.0)) > 0
                behind.append({k for k, h in zip(posts.names, hidden, strict=True) if h})
                out.occluded_at[obs.index, e] = behind[e]
            ends = tuple(
                {k: v for k, v in b.items() if k not in behind[e]} for e, b in enumerate(ends)
            )
        if view_rad is not None:
            lo, hi = view_rad
            ends = tuple({k: v for k, v in b.items() if k[0] == "L" or lo <= v <= hi} for b in ends)
        unique = tuple(
            {k: v for k, v in b.items() if k[0] == "L" and not (hide and hide(obs.index, e, k))}
            for e, b in enumerate(ends)
        )
        seen = [
            [(k, v) for k, v in b.items() if k[0] == "B" and not (hide and hide(obs.index, e, k))]
            for e, b in enumerate(ends)
        ]
        for s in seen:
            rng.shuffle(s)  # blobs come in no particular order
        blobs = tuple({"blue": [v for _, v in s]} for s in seen)
        for e, per_class in enumerate(blobs):
            keyframe_blobs[obs.index, e] = per_class
            true_of[obs.index, e] = [k for k, _ in seen[e]]
        t_movement, t_assoc = time.process_time(), time.perf_counter()
        a = assoc.associate(obs.index, (unique[0], unique[1]), (blobs[0], blobs[1]), slam.estimates)
        out.association_seconds += time.perf_counter() - t_assoc
        res = slam.process_movement(
            MovementObservation(
                obs.index, {**unique[0], **a.bearings_o1_rad}, {**unique[1], **a.bearings_o2_rad}
            )
        )
        trajectory = slam.movement_poses()  # type: ignore[attr-defined]
        pose = trajectory.get(obs.index) if res.status == "ok" else None
        t_assoc = time.perf_counter()
        assoc.hypothesize(a, pose, slam.estimates, trajectory, slam.bearing_scatter)  # type: ignore[attr-defined]
        out.association_seconds += time.perf_counter() - t_assoc
        for name in a.retracted:
            slam.forget(name)
        for name, hist in a.history.items():
            slam.add_history(name, hist)  # type: ignore[attr-defined]
        out.results.append(a)
        out.movement_cpu_seconds.append(time.process_time() - t_movement)
        for e in (0, 1):
            for j, name in enumerate(a.names.get("blue", ([], []))[e]):
                if name is not None and name not in a.confirmed:
                    out.given.append((obs.index, e, name, seen[e][j][0]))
    out.seconds = time.perf_counter() - tick
    tick = time.perf_counter()
    final, _ = assoc.associate_final(
        keyframe_blobs,
        slam.keyframe_poses(),  # type: ignore[attr-defined]
        slam.estimates,
        slam.noise.sigma_rad,  # type: ignore[attr-defined]
    )
    out.final_seconds = time.perf_counter() - tick
    at = {key: iter(names) for key, names in true_of.items()}  # final keeps the blobs' order
    out.final = [(d, next(at[d.movement, d.end])) for d in final]
    out.estimates_fl = {k: e.mean_fl for k, e in slam.estimates.items() if "#" in k}
    poses = slam.keyframe_poses()  # type: ignore[attr-defined]
    tick = time.perf_counter()  # last: what it changes is not scored here
    assoc.repair_final(final, poses, slam.estimates, obs.index)
    out.repair_seconds = time.perf_counter() - tick
    return out
