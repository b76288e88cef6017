"""Whether a processed log's map can be trusted, from its summary document.

A map is not trustworthy when its own evidence says so: a class of look-alike landmarks has
detections that no name explains with the final map (a landmark missing, or a name where rays
of several landmarks meet), names are doubtful, unconfirmed, weak with the final map, or placed
only loosely (their region reaching farther than :data:`LOOSE_M`, at 99 % for the run's names
together: :data:`LOOSE_RUN_RISK`; flagged one by one), or a landmark's bearings scatter about
it far more widely than the map's do (detections of several landmarks under one name), or the
bearings of several movements do not fit the map (they were skipped as not fitting it, or the
map diverged with them), or fewer than half of the movements are in the map, or the map has
collapsed (landmarks where the robot stood). The verdict is a
result, not an error: ``bslam process`` says it and exits 0.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from pipeline.association.support import DOUBT_SCATTER, DOUBT_SCATTER_BEARINGS
from pipeline.estimate import chi2_2dof_quantile
from pipeline.geometry import widest_std
from pipeline.joint.noise import robust_std
from pipeline.joint.robustness import COLLAPSE_FL, REJECT_EPS

#: This many movements skipped because their bearings did not fit the map make it doubtful.
MISFIT_MOVEMENTS = 2
#: Statuses of movements skipped because their bearings did not fit the map.
MISFIT_STATUSES = ("does not fit the map", "the map diverged")
#: A name of a shared class whose region (the map's covariance, at :data:`LOOSE_RUN_RISK` for the
#: run's names together) reaches farther than this from its point, along its widest axis, is
#: flagged by name: the map cannot tell it within this distance, and a name that far off is
#: wrong for a user.
LOOSE_M = 0.10
#: The chance, under the map's own covariances, that any name of the run the region test leaves
#: unflagged is farther than :data:`LOOSE_M` from its point: with n names of shared classes each
#: region is taken at level 1 - LOOSE_RUN_RISK / n (Bonferroni). A user reads every name of a
#: run at once: a region at 99 % for each of 16 names leaves a name outside its region in about
#: one run of seven.
LOOSE_RUN_RISK = 0.01
#: A landmark with at least this many recorded bearings (``residuals_deg`` of the movements),
#: more than half of them beyond :data:`~pipeline.joint.robustness.REJECT_EPS` eps of the map,
#: is flagged by name. The bearing error is bounded by eps, so such a residual is a wrong
#: detection or a wrong map; where the map holds a landmark right, its wrong detections are the
#: exception (docs/RESULTS.md, "Trust verdict on the arena families").
UNFIT_MIN_BEARINGS = 6


def trust_reasons(doc: dict[str, Any]) -> list[str]:
    """Why the map of a summary document is not trustworthy (empty: nothing says so)."""
    reasons = []
    moves = doc.get("movements", [])
    used = sum(1 for m in moves if m.get("status") == "ok")
    if moves and 2 * used < len(moves):
        reasons.append(f"only {used} of {len(moves)} movements are in the map")
    misfit = [m["index"] for m in moves if any(s in m.get("status", "") for s in MISFIT_STATUSES)]
    if len(misfit) >= MISFIT_MOVEMENTS:
        reasons.append(
            f"the bearings of movement(s) {', '.join(map(str, misfit))} do not fit the map"
        )
    collapsed = _collapsed(doc)
    if collapsed:
        reasons.append(
            f"the map collapsed: {', '.join(collapsed)} where the robot stood (a degenerate fit)"
        )
    assoc = doc.get("association") or {}
    for label, c in sorted(assoc.get("final_map", {}).items()):
        if "warning" in c:
            reasons.append(f"detections of {label} that no name explains")
    for key in ("doubtful", "unconfirmed"):
        names = assoc.get(key) or {}
        if names:
            reasons.append(f"{key} name(s) {', '.join(sorted(names))}")
    weak = sorted(n for c in assoc.get("final_map", {}).values() for n in c.get("weak", {}))
    if weak:
        reasons.append(
            f"weak name(s) {', '.join(weak)} (with the final map, too few detections, "
            "detections that do not meet at one point, or a missing landmark in line with it)"
        )
    unfit = _unfit(doc)
    ref = {doc.get("frame", {}).get(k) for k in ("origin", "x_axis")}
    for name, far, n in unfit:
        if name in ref:
            reasons.append(
                f"{far} of {n} bearings of the reference landmark {name} lie more than "
                f"{REJECT_EPS:g} eps from the map: the map's frame rests on it"
            )
    others = [f"{name} ({far} of {n})" for name, far, n in unfit if name not in ref]
    if others:
        reasons.append(
            f"landmark(s) {', '.join(others)} whose bearings mostly lie more than "
            f"{REJECT_EPS:g} eps from the map (it stands elsewhere, or its detections are "
            "another's)"
        )
    unfit_names = {name for name, _, _ in unfit}
    scattered = [f"{n} ({ratio:.1f}x)" for n, ratio in _scattered(doc) if n not in unfit_names]
    if scattered:
        reasons.append(
            f"landmark(s) {', '.join(scattered)} whose bearings scatter about the map that many "
            "times as widely as the map's bearings do (its detections may be of several "
            "landmarks)"
        )
    loose = _loose(doc)
    if loose:
        reasons.append(
            f"name(s) {', '.join(loose)} placed only to within {100 * LOOSE_M:.0f} cm or worse "
            f"(their regions at {100 * (1 - LOOSE_RUN_RISK):.0f} % for the run's names together)"
        )
    return reasons


def _loose(doc: dict[str, Any]) -> list[str]:
    """Names of shared classes (``label#k``) whose region, at level 1 - :data:`LOOSE_RUN_RISK`
    / n for the run's n such names, reaches farther than :data:`LOOSE_M` from their point
    (none when the map's unit is unknown)."""
    unit_m = doc.get("map_unit_m")
    named = {n: e for n, e in doc.get("landmarks", {}).items() if "#" in n}
    if not unit_m or not named:
        return []
    scale = math.sqrt(chi2_2dof_quantile(1.0 - LOOSE_RUN_RISK / len(named)))
    out = []
    for name, est in named.items():
        cov = est.get("cov")
        if cov is not None and scale * widest_std(np.asarray(cov, np.float64)) * unit_m > LOOSE_M:
            out.append(name)
    return sorted(out, key=lambda n: (n.rpartition("#")[0], int(n.rpartition("#")[2])))


def _unfit(doc: dict[str, Any]) -> list[tuple[str, int, int]]:
    """Landmarks with at least :data:`UNFIT_MIN_BEARINGS` recorded bearings, more than half of
    them beyond :data:`~pipeline.joint.robustness.REJECT_EPS` eps of the map: (name, how many
    beyond, how many), in the order first recorded (none when eps is unknown)."""
    eps_deg = (doc.get("method") or {}).get("vision_error_deg")
    if not eps_deg:
        return []
    bound = REJECT_EPS * float(eps_deg)
    out = []
    for name, r in _recorded_residuals_deg(doc).items():
        far = sum(abs(x) > bound for x in r)
        if len(r) >= UNFIT_MIN_BEARINGS and 2 * far > len(r):
            out.append((name, far, len(r)))
    return out


def _recorded_residuals_deg(doc: dict[str, Any]) -> dict[str, list[float]]:
    """Every landmark's recorded bearing residuals (``residuals_deg`` of the movements, deg),
    the landmarks in the order first recorded."""
    out: dict[str, list[float]] = {}
    for m in doc.get("movements", []):
        for name, ends in (m.get("residuals_deg") or {}).items():
            out.setdefault(name, []).extend(r for r in ends if r is not None)
    return out


def _scattered(doc: dict[str, Any]) -> list[tuple[str, float]]:
    """Landmarks not of a shared class (a name without ``#``: association judges those) with at
    least :data:`~pipeline.association.support.DOUBT_SCATTER_BEARINGS` recorded bearings whose
    residuals scatter more than :data:`~pipeline.association.support.DOUBT_SCATTER` times as
    widely as the map's bearing noise (robust scale over the noise): (name, ratio), in the order
    first recorded (none without a noise estimate). Rays of one landmark meet at its point to
    within the noise; a detector that also reads another landmark's blob as this one gives it
    rays that meet at two points."""
    noise_deg = doc.get("bearing_noise_deg")
    if not noise_deg:
        return []
    out = []
    for name, r in _recorded_residuals_deg(doc).items():
        if "#" in name or len(r) < DOUBT_SCATTER_BEARINGS:
            continue
        ratio = robust_std(np.asarray(r, np.float64)) / float(noise_deg)
        if ratio > DOUBT_SCATTER:
            out.append((name, ratio))
    return out


def _collapsed(doc: dict[str, Any]) -> list[str]:
    """Landmarks of the final map within :data:`COLLAPSE_FL` of a keyframe of the map."""
    points = [
        p for m in doc.get("movements", []) for p in (m.get("observation_points") or {}).values()
    ]
    out = []
    for name, est in doc.get("landmarks", {}).items():
        x, y = est["mean"]
        if any(math.hypot(x - px, y - py) < COLLAPSE_FL for px, py in points):
            out.append(name)
    return out


def trust_entry(reasons: Sequence[str]) -> dict[str, Any]:
    """The summary's ``trust`` entry from :func:`trust_reasons`: ``trustworthy`` and, when not,
    ``reasons``."""
    reasons = list(reasons)
    return {"trustworthy": not reasons, **({"reasons": reasons} if reasons else {})}
