"""What the joint estimator returns per movement (no gtsam needed to read it)."""

from __future__ import annotations

from dataclasses import dataclass, field

from pipeline.joint.noise import NoiseEstimate
from pipeline.slam import MovementResult, Placement


@dataclass
class JointMovementResult(MovementResult):
    """A :class:`pipeline.slam.MovementResult` with what the joint estimator adds.

    The particle fields (``particles_fr``, ``particles_fl``, ``belief_fl``, ``cones_fr``) are the
    initializer's (the paper's filter); ``estimates``, ``o1_fl`` and ``o2_fl`` are the joint map's.

    Attributes
    ----------
    placement : Placement
        ``REFERENCE_PAIR`` (the paper could use the movement too), ``RESECTION`` (placed
        against the landmarks in the map) or ``NONE`` (skipped).
    also_placed : list of int
        Earlier movements that waited (not placeable then) and entered the map with this one.
    residuals_rad : dict name -> (at O1, at O2)
        This movement's bearing residuals under the map after it (None: not in the graph).
    noise : NoiseEstimate or None
        Bearing noise estimated from every residual of the map.
    divergence : str
        Empty, or why the map was re-initialized from the particles this movement.
    solved_again : str
        Empty, or why the map was found stuck away from its optimum after this movement and
        replaced by a solve of its whole record.
    unit_m : float or None
        The map's unit |L1 L2| in metres, estimated from the driven distances (None without
        the distance prior, or before a movement with a distance is in the map).
    """

    placement: Placement = Placement.NONE
    also_placed: list[int] = field(default_factory=list)
    residuals_rad: dict[str, tuple[float | None, float | None]] = field(default_factory=dict)
    noise: NoiseEstimate | None = None
    divergence: str = ""
    solved_again: str = ""
    unit_m: float | None = None
