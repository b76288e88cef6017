"""What the joint map is made of, as plain data: its settings, its movements and its state.

:class:`MapState` is the one object a rollback restores (the movements placed or waiting, the
landmarks in the graph and the bearings waiting for theirs, the rejected bearings, the estimates
and the bearing noise, and the movements marginalized out of the graph with the prior they
left: :class:`FrozenMovement`, :class:`FrozenBearings`); everything else of the joint
estimator (the iSAM2 graph, the bearing table, the factor indices:
:class:`pipeline.joint.mapgraph.MapGraph`) is derived from it and rebuilt after a rollback.
The parts of the estimator receive the state as an argument and change it in place; none of
them keeps it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import gtsam
import numpy as np
from numpy.typing import NDArray

from pipeline.estimate import LandmarkEstimate
from pipeline.joint import graph as g
from pipeline.joint.noise import NoiseEstimate
from pipeline.slam import MovementObservation


@dataclass(frozen=True)
class JointSettings:
    """The joint estimator's settings, fixed for one map.

    Attributes
    ----------
    landmarks : tuple of str
        The catalog, in catalog order (a landmark's index is its graph key's).
    reference : (str, str)
        The reference pair L1, L2 (the gauge: (0, 0) and (1, 0) FL).
    eps_rad : float
        The bearing error bound eps (rad).
    sigma0_rad : float
        The bearing std the map starts with (rad; eps as a truncated Gaussian).
    robust : bool
        Huber loss on the bearing factors.
    turn_prior_sigma_rad : float or None
        Std (rad) of the prior on each turn in place from the commanded turn; None: free.
    distance_prior_rel : float or None
        Relative std of the prior on each movement's length from its driven distance; None:
        no prior.
    divergence_rms_rad : float
        Robust residual RMS (rad) above which the map counts as diverged.
    index : dict of str to int
        Catalog index of each landmark name (derived from ``landmarks``).
    """

    landmarks: tuple[str, ...]
    reference: tuple[str, str]
    eps_rad: float
    sigma0_rad: float
    robust: bool
    turn_prior_sigma_rad: float | None
    distance_prior_rel: float | None
    divergence_rms_rad: float

    index: Mapping[str, int] = field(init=False, repr=False, compare=False)
    _keys: Mapping[str, int] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "index", {n: i for i, n in enumerate(self.landmarks)})
        keys = {n: g.landmark_key(i) for n, i in self.index.items()}
        object.__setattr__(self, "_keys", keys)

    def key(self, name: str) -> int:
        """Graph key of landmark ``name``."""
        return self._keys[name]

    def reference_indices(self) -> list[int]:
        """Catalog indices of the reference pair."""
        return [self.index[n] for n in self.reference]


@dataclass
class Movement:
    """A movement's bearings (catalog landmarks, finite), commanded turn and driven distance."""

    index: int
    turn_rad: float | None
    bearings: list[g.Bearing]
    distance_m: float | None = None

    def observation(self) -> MovementObservation:
        """The bearings back as a :class:`MovementObservation`."""
        ends: tuple[dict[str, float], dict[str, float]] = ({}, {})
        for b in self.bearings:
            ends[b.end][b.landmark] = b.bearing_rad
        return MovementObservation(self.index, ends[0], ends[1], self.turn_rad, self.distance_m)


@dataclass(frozen=True)
class FrozenMovement:
    """A movement marginalized out of the graph (:mod:`pipeline.joint.window`), as it was then.

    Attributes
    ----------
    movement : Movement
        Its bearings, turn and distance.
    poses : ((x, y, heading), (x, y, heading))
        Its keyframes O1 and O2 (FL, rad).
    covs : ((3, 3) array or None, (3, 3) array or None)
        Their tangent covariances in the whole map then (at the noise model; None: not
        determined).
    """

    movement: Movement
    poses: tuple[tuple[float, float, float], tuple[float, float, float]]
    covs: tuple[NDArray[np.float64] | None, NDArray[np.float64] | None]


@dataclass(frozen=True)
class FrozenBearings:
    """Bearings of keyframes no longer in the graph, with the residual each had when its
    keyframe left: landmark catalog index, residual (rad) and whether it was rejected, (n,)
    each. Never changed in place (a change makes a new object)."""

    landmark: NDArray[np.int64]
    residual_rad: NDArray[np.float64]
    rejected: NDArray[np.bool_]

    @staticmethod
    def empty() -> FrozenBearings:
        """No bearings."""
        return FrozenBearings(np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.bool_))

    def plus(
        self,
        landmark: NDArray[np.int64],
        residual_rad: NDArray[np.float64],
        rejected: NDArray[np.bool_],
    ) -> FrozenBearings:
        """These bearings and more."""
        return FrozenBearings(
            np.concatenate([self.landmark, landmark]),
            np.concatenate([self.residual_rad, residual_rad]),
            np.concatenate([self.rejected, rejected]),
        )

    def without(self, landmark: int) -> FrozenBearings:
        """These bearings less those of one landmark."""
        keep = self.landmark != landmark
        return FrozenBearings(self.landmark[keep], self.residual_rad[keep], self.rejected[keep])

    def __len__(self) -> int:
        return int(self.landmark.size)


@dataclass
class MapState:
    """What a rollback restores: the movements (placed in the graph, or waiting), the links
    between consecutive placed movements, the landmarks in the graph and the bearings waiting
    for theirs, the rejected bearings, the landmark estimates and the bearing noise.

    Attributes
    ----------
    placed, waiting : dict of int to Movement
        Movements in the graph, and those not placed yet, by index.
    links : set of (int, int)
        Consecutive placed movements joined by a turn in place.
    in_graph : set of str
        Landmarks in the graph (the reference pair from the start).
    pending : dict of str to list of Bearing
        Bearings of placed movements whose landmark is not in the graph yet.
    rejected : set of Bearing
        Bearings taken out of the graph as wrong detections.
    estimates : dict of str to LandmarkEstimate
        The last estimate of every non-reference landmark in the graph (FL).
    noise : NoiseEstimate or None
        The bearing noise estimated from the residuals (None before a map).
    sigma_model_rad : float
        The bearing std the bearing factors are weighted with.
    frozen : dict of int to FrozenMovement
        Movements marginalized out of the graph (replaced, never changed in place).
    frozen_links : int
        Links that joined a frozen movement.
    prior : gtsam.NonlinearFactor or None
        What the frozen movements' factors say about the variables still in the graph (one
        linear factor; :mod:`pipeline.joint.window`).
    frozen_bearings : FrozenBearings
        The frozen movements' bearings of landmarks in the graph, with their residuals then.
    """

    placed: dict[int, Movement]
    waiting: dict[int, Movement]
    links: set[tuple[int, int]]
    in_graph: set[str]
    pending: dict[str, list[g.Bearing]]
    rejected: set[g.Bearing]
    estimates: dict[str, LandmarkEstimate]
    noise: NoiseEstimate | None
    sigma_model_rad: float
    frozen: dict[int, FrozenMovement] = field(default_factory=dict)
    frozen_links: int = 0
    prior: gtsam.NonlinearFactor | None = None
    frozen_bearings: FrozenBearings = field(default_factory=FrozenBearings.empty)

    @classmethod
    def empty(cls, settings: JointSettings) -> MapState:
        """No movement yet: the reference pair in the graph, the model's std at its start."""
        return cls(
            placed={},
            waiting={},
            links=set(),
            in_graph=set(settings.reference),
            pending={},
            rejected=set(),
            estimates={},
            noise=None,
            sigma_model_rad=settings.sigma0_rad,
        )

    def copy(self) -> MapState:
        """A copy whose containers are new (the movements themselves are shared)."""
        return MapState(
            dict(self.placed),
            dict(self.waiting),
            set(self.links),
            set(self.in_graph),
            {k: list(v) for k, v in self.pending.items()},
            set(self.rejected),
            dict(self.estimates),
            self.noise,
            self.sigma_model_rad,
            self.frozen,  # the frozen part is replaced, never changed in place
            self.frozen_links,
            self.prior,
            self.frozen_bearings,
        )

    def n_params(self) -> int:
        """Free parameters of the keyframes and landmarks. The bearings still determine them
        with a distance prior, whose std is loose against the lengths the bearings give: not
        counting its share keeps the noise estimate on the safe side."""
        return (
            2 * (len(self.in_graph) - 2)
            + 4 * (len(self.placed) + len(self.frozen))
            - 2 * (len(self.links) + self.frozen_links)
        )

    def covariance_scale(self) -> float:
        """Factor from iSAM2's covariances (weighted with the model's std) to those of the
        estimated noise (1 before a noise estimate)."""
        if self.noise is None:
            return 1.0
        return self.noise.variance_rad2 / self.sigma_model_rad**2

    def links_of(self, k: int) -> list[tuple[int, int]]:
        """In-place links of movement ``k`` to its placed neighbours."""
        return [(a, b) for a, b in ((k - 1, k), (k, k + 1)) if {a, b} - {k} <= set(self.placed)]

    def bearings(self, rejected: bool = True) -> list[g.Bearing]:
        """Every bearing of the placed movements whose landmark is in the graph (with or
        without the rejected ones), in movement order."""
        return [
            b
            for k in sorted(self.placed)
            for b in self.placed[k].bearings
            if b.landmark in self.in_graph and (rejected or b not in self.rejected)
        ]
