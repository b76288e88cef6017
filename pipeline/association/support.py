"""What became of a named landmark's predicted sightings since it was named, and when that is
too little to trust the name.

A landmark of a shared class is named from a few rays (four lines of sight over two
movements). Rays of several landmarks can meet by chance, and such a name fits those few rays
as well as a real landmark does, so its residuals do not give it away then. What does: from the
keyframes that come after, a real landmark is mostly seen where the map predicts it, a point
where no landmark stands mostly is not (its predictions meet no blob, or a blob another
landmark explains as well); and when it is seen, it is in turn by landmarks that line up with
it, whose bearings in the map scatter about it more widely than a real landmark's do.
:class:`Support` counts each prediction's outcome and keeps the estimator's scatter;
:meth:`Support.doubt` says when the name is doubtful: seen at too small a share of its
predictions, never seen, or missed (no detection of its class in its gate) too often. A name
found by the search among unnamed detections (from rays the hypotheses kept disputing) is
weaker evidence: seen at half its predictions or fewer and contested at 35 % of them or
more, it is doubtful too. A name whose bearings scatter too widely is doubtful. How the
thresholds were chosen is in docs/RESULTS.md ("Landmarks that look alike: association"). A
name seen at too few keyframes since its naming for either to show is unconfirmed
(:meth:`Support.unconfirmed`): reported, as the name has not yet been put to the test.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad
from pipeline.association.jcbb import chi2_quantile
from pipeline.geometry import bearing_point

#: What became of one prediction at one keyframe: the landmark got a detection ("seen"), none
#: was in its gate ("missed"), several landmarks or detections were ("contested"), the
#: prediction was too uncertain to gate anything ("vague"), or a nearer landmark in line with
#: it took the one detection in its gate ("hidden": not a test of the name, not counted as
#: predicted).
Outcome = Literal["seen", "missed", "contested", "vague", "hidden"]

#: A name is doubtful once it has been predicted at this many keyframes since it was named...
DOUBT_MIN_PREDICTIONS = 6
#: ... and seen at fewer than this share of them,
DOUBT_SEEN_SHARE = 1.0 / 3.0
#: or predicted at this many and seen at none,
DOUBT_NEVER_SEEN = 2
#: or predicted at DOUBT_MIN_PREDICTIONS and missed (no detection of its class in its gate) at
#: this share of them or more.
DOUBT_MISSED_SHARE = 0.2
#: A name found by the search among unnamed detections (rays the hypotheses kept disputing)
#: is also doubtful once predicted at DOUBT_MIN_PREDICTIONS keyframes, seen at no more than this
#: share of them...
DOUBT_SEARCHED_SEEN_SHARE = 0.5
#: ... and contested at this share or more: its blobs are as often another landmark's.
DOUBT_SEARCHED_CONTESTED_SHARE = 0.35
#: A name is also doubtful when it has this many bearings in the map...
DOUBT_SCATTER_BEARINGS = 10
#: ... and they scatter about it this many times as widely as the map's bearings do (robust
#: scales; :attr:`pipeline.joint.JointSlam.bearing_scatter`): rays of several landmarks meet
#: only roughly.
DOUBT_SCATTER = 1.7
#: A name not doubtful is confirmed once seen at this many keyframes since it was named (two
#: movements' worth, beyond the lines of sight or the keyframes that named it).
CONFIRM_MIN_SEEN = 4
#: With the final map, a name whose detections do not meet at one point is flagged
#: (:func:`misfit`): their squared residuals about the point that fits them best, each in units
#: of its prediction's variance, beyond the chi-square quantile (n - 2 dof) at level
#: 1 - MISFIT_RUN_RISK / k for the run's k names (Bonferroni: the chance that any name of a run
#: whose detections are all its own landmark's is flagged is at most this).
MISFIT_RUN_RISK = 0.01
#: ... tested from this many detections (two fix the point).
MISFIT_MIN_RAYS = 4


@dataclass
class Support:
    """Outcomes of a named landmark's predictions since it was named.

    Attributes
    ----------
    named_at : int
        The movement that named it (its own keyframes are not counted: they named it).
    seen, missed, contested, vague, hidden : int
        Keyframes since then where its prediction had that outcome.
    scatter : (int, float) or None
        Its bearings in the map and how widely they scatter about it (the estimator's
        :attr:`~pipeline.joint.JointSlam.bearing_scatter`; None: not known).
    searched : bool
        Named by the search among unnamed detections, not from a hypothesis.
    """

    named_at: int
    seen: int = 0
    missed: int = 0
    contested: int = 0
    vague: int = 0
    hidden: int = 0
    scatter: tuple[int, float] | None = None
    searched: bool = False

    @property
    def predicted(self) -> int:
        """Keyframes where it was predicted since it was named (hidden ones aside)."""
        return self.seen + self.missed + self.contested + self.vague

    @property
    def confirmed(self) -> bool:
        """Seen often enough since its naming to tell, and not doubtful."""
        return self.seen >= CONFIRM_MIN_SEEN and self.doubt() is None

    def add(self, outcome: Outcome) -> None:
        """Count one prediction's outcome."""
        setattr(self, outcome, getattr(self, outcome) + 1)

    def doubt(self) -> str | None:
        """Why the name is doubtful (None: it is not)."""
        n = self.predicted
        never = n >= DOUBT_NEVER_SEEN and self.seen == 0
        rare = self.seen < DOUBT_SEEN_SHARE * n or self.missed >= DOUBT_MISSED_SHARE * n
        if never or (n >= DOUBT_MIN_PREDICTIONS and rare):
            return (
                f"seen at {self.seen} of {n} keyframes where predicted since it was named "
                f"(movement {self.named_at}; {self.missed} missed, {self.contested} contested, "
                f"{self.vague} too uncertain): it may stand where rays of several landmarks meet"
            )
        shared = (
            self.seen <= DOUBT_SEARCHED_SEEN_SHARE * n
            and self.contested >= DOUBT_SEARCHED_CONTESTED_SHARE * n
        )
        if self.searched and n >= DOUBT_MIN_PREDICTIONS and shared:
            return (
                f"found by the search among unnamed detections (movement {self.named_at}), "
                f"then seen at only {self.seen} of {n} keyframes where predicted and contested "
                f"at {self.contested}: its blobs are as often other landmarks'; it may stand "
                "where their rays meet"
            )
        if self.scatter is None:
            return None
        count, ratio = self.scatter
        if count < DOUBT_SCATTER_BEARINGS or ratio <= DOUBT_SCATTER:
            return None
        return (
            f"its {count} bearings in the map scatter {ratio:.1f} times as widely as the "
            "map's bearings do: they may come from several landmarks"
        )

    def unconfirmed(self) -> str | None:
        """Why the name is not confirmed yet (None: it is, or it is doubtful instead)."""
        if self.seen >= CONFIRM_MIN_SEEN or self.doubt() is not None:
            return None
        return (
            f"seen at {self.seen} keyframe(s) since it was named (movement {self.named_at}); "
            f"{CONFIRM_MIN_SEEN} confirm a name"
        )


def misfit(
    origins_fl: NDArray[np.float64],
    directions_rad: NDArray[np.float64],
    var_rad2: NDArray[np.float64],
    point_fl: NDArray[np.float64],
    names: int,
) -> str | None:
    """Why a name's detections do not meet at one point (None: they do, or are too few).

    Rays of two landmarks a few degrees apart, or of a landmark and a keyframe placed wrong,
    each fit a point well enough to be gated, yet together they leave residuals the map's
    noise does not explain. The test: the point that minimises the squared bearing residuals
    (Gauss-Newton from ``point_fl``, each ray weighted by its variance) and the sum of those
    squared residuals against the chi-square quantile with n - 2 degrees of freedom at level
    1 - :data:`MISFIT_RUN_RISK` / ``names``.

    Parameters
    ----------
    origins_fl : (n, 2) float
        Where each detection was made (its keyframe), FL.
    directions_rad : (n,) float
        Each detection's direction, FL (keyframe heading plus bearing), rad.
    var_rad2 : (n,) float
        Each detection's variance about the true bearing (bearing noise and the keyframe
        pose's), rad^2.
    point_fl : (2,) float
        Where the map holds the name, FL: the fit starts there.
    names : int
        Names of the run tested together (k of the Bonferroni level).
    """
    n = len(directions_rad)
    if n < MISFIT_MIN_RAYS:
        return None
    w = 1.0 / np.asarray(var_rad2, np.float64)
    p = bearing_point(origins_fl, directions_rad, point_fl, w, steps=10, tol=1e-16, min_det=1e-18)
    d = p - origins_fl
    stat = float(np.sum(w * wrap_rad(directions_rad - np.arctan2(d[:, 1], d[:, 0])) ** 2))
    level = 1.0 - MISFIT_RUN_RISK / max(names, 1)
    bound = chi2_quantile(n - 2, level)
    if stat <= bound:
        return None
    return (
        f"its {n} detections with the final map do not meet at one point: their squared "
        f"residuals sum to {stat:.0f} noise variances, beyond the {bound:.0f} of one "
        f"landmark's ({n - 2} dof, {100 * level:.2f} %): they may come from several landmarks"
    )
