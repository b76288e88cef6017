"""Graph bookkeeping of the joint map: the iSAM2 handle, its values, factors and bearing table.

:class:`MapGraph` holds what is derived from the map's state (:class:`MapState`) and rebuilt
after a rollback: the iSAM2 instance and its parameters, the current estimate of every variable,
the iSAM2 index of each bearing factor, the map's bearings as arrays (:class:`BearingTable`) and
their residuals. It puts a placed movement into the graph (poses, constraints, bearings), lets
landmarks enter the graph when their rays meet, starts the map with one batch solve (the
bootstrap), rebuilds iSAM2 over every factor, and turns iSAM2's marginals into the map's
estimates. The state is passed to every call that reads or changes it; the graph never keeps it.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Collection, Iterable, Mapping, Sequence

import gtsam
import numpy as np
from numpy.typing import NDArray

from pipeline.estimate import LandmarkEstimate
from pipeline.geometry import KeyframePose, MovementPose, intersect_rays, widest_std
from pipeline.joint import graph as g
from pipeline.joint.noise import estimate_noise, robust_std
from pipeline.joint.state import JointSettings, MapState, Movement
from pipeline.joint.table import BearingTable

#: Smallest angle between two rays of a landmark for it to enter the graph by intersection, in
#: units of eps (the paper's own bound for a usable cone intersection is 2 eps).
MIN_RAY_PARALLAX_EPS = 2.0
#: A particle belief of the initializer this tight (sqrt of the largest covariance eigenvalue,
#: FL) puts its landmark in the graph at the belief's mean.
TIGHT_BELIEF_FL = 0.1
#: The model's noise is re-tuned (graph rebuilt) when the estimate leaves this ratio band ...
RETUNE_RATIO = 1.5
#: ... with at least this many degrees of freedom.
RETUNE_DOF = 10
#: Up to this many movements the map is solved carefully: Powell's dogleg steps, QR, relinearization
#: threshold 1e-3 and one more step after every update (a Gauss-Newton step from the bootstrap's
#: optimum along a barely determined direction can throw the map away); from then on, with the
#: map determined, plain Gauss-Newton steps (Cholesky) relinearized per variable, whose cost per
#: movement does not grow with the dogleg's steps over the whole tree.
CAREFUL_MOVEMENTS = 50
#: After the careful movements, iSAM2 looks for variables to relinearize at every this many
#: updates (GTSAM's default; every update: twice the cost of the update, no gain in accuracy).
RELINEARIZE_SKIP = 10


def pose2s(pose: MovementPose) -> tuple[gtsam.Pose2, gtsam.Pose2]:
    """A movement's two keyframes as GTSAM poses (O1, O2; FL, both with its heading)."""
    o2 = pose.o2_fl
    return (
        gtsam.Pose2(float(pose.o1_fl[0]), float(pose.o1_fl[1]), pose.heading_rad),
        gtsam.Pose2(float(o2[0]), float(o2[1]), pose.heading_rad),
    )


class MapGraph:
    """The joint map's factor graph in iSAM2, and what is derived from it.

    Parameters
    ----------
    settings : JointSettings
        The estimator's settings.

    Attributes
    ----------
    settings : JointSettings
        As given.
    isam : gtsam.ISAM2
        The incremental solver (replaced by a rebuild).
    careful : bool
        Whether ``isam`` was made for a map of fewer than :data:`CAREFUL_MOVEMENTS` movements.
    table : BearingTable
        Every bearing of the map (rows: placed movements, landmark in the graph).
    factor_of : dict of Bearing to int
        iSAM2 factor index of each bearing in the graph (rejected ones are not).
    """

    def __init__(self, settings: JointSettings) -> None:
        self.settings = settings
        self.factor_of: dict[g.Bearing, int] = {}
        # bearing factors added to a graph not yet given to iSAM2: (position in it, bearing)
        self._staged: list[tuple[int, g.Bearing]] = []
        # the map's bearings as arrays, and their residuals at the map as it is (residuals)
        self.table = BearingTable()
        self._residual_memo: tuple[gtsam.Values, int, NDArray[np.float64]] | None = None
        self.careful = True
        self.isam = self.new_isam(0)
        # iSAM2's estimate of every variable, computed when first asked after an update
        self._estimate: gtsam.Values | None = gtsam.Values()
        # landmark positions read from an estimate (that estimate, by name)
        self._points: tuple[gtsam.Values | None, dict[str, NDArray[np.float64]]] = (None, {})

    # ------------------------------------------------------------------ iSAM2 and values
    def new_isam(self, n_placed: int) -> gtsam.ISAM2:
        """A fresh iSAM2 for a map of ``n_placed`` movements, careful while it has fewer than
        :data:`CAREFUL_MOVEMENTS`."""
        self.careful = n_placed < CAREFUL_MOVEMENTS
        params = gtsam.ISAM2Params()
        params.relinearizeSkip = 1
        if self.careful:
            params.setFactorization("QR")
            params.setRelinearizeThreshold(1e-3)
            params.setOptimizationParams(gtsam.ISAM2DoglegParams())
        else:  # GTSAM's default factorization (Cholesky) and relinearization check
            params.relinearizeSkip = RELINEARIZE_SKIP
            params.setRelinearizeThreshold(g.relinearize_thresholds())
            params.enablePartialRelinearizationCheck = True
            params.setOptimizationParams(gtsam.ISAM2GaussNewtonParams())
        return gtsam.ISAM2(params)

    @property
    def values(self) -> gtsam.Values:
        """Every variable as iSAM2 estimates it now (one back-substitution after an update,
        then kept until the next; never changed in place)."""
        if self._estimate is None:
            self._estimate = self.isam.calculateEstimate()
        return self._estimate

    @values.setter
    def values(self, values: gtsam.Values) -> None:
        self._estimate = values

    def key(self, name: str) -> int:
        """Graph key of landmark ``name``."""
        return self.settings.key(name)

    def point(self, name: str) -> NDArray[np.float64]:
        """Position (2,) FL of a landmark in the graph (a new array)."""
        if self._estimate is None:  # one variable, not the whole map
            return np.asarray(self.isam.calculateEstimatePoint2(self.key(name)), np.float64)
        if self._points[0] is not self._estimate:  # read once per estimate and landmark
            self._points = (self._estimate, {})
        memo = self._points[1]
        if name not in memo:
            memo[name] = np.asarray(self._estimate.atPoint2(self.key(name)), np.float64)
        return memo[name].copy()

    def has(self, key: int) -> bool:
        """Whether variable ``key`` is in the graph."""
        if self._estimate is None:
            return bool(self.isam.valueExists(key))
        return bool(self._estimate.exists(key))

    def pose2(self, key: int) -> gtsam.Pose2:
        """Keyframe ``key`` as estimated now."""
        if self._estimate is None:
            return self.isam.calculateEstimatePose2(key)
        return self.values.atPose2(key)

    def movement_pose(self, movement: int, values: gtsam.Values | None = None) -> MovementPose:
        """A placed movement's pose, as estimated now or in ``values``."""
        k1, k2 = g.pose_key(movement, 0), g.pose_key(movement, 1)
        if values is None:
            p1, p2 = self.pose2(k1), self.pose2(k2)
        else:
            p1, p2 = values.atPose2(k1), values.atPose2(k2)
        return MovementPose.from_ends(
            np.array([p1.x(), p1.y()]), p1.theta(), np.array([p2.x(), p2.y()])
        )

    def unit_m(self) -> float | None:
        """The map's unit |L1 L2| in metres from the scale variable (None without it)."""
        if not self.has(g.SCALE_KEY):
            return None
        if self._estimate is None:
            return math.exp(-float(self.isam.calculateEstimateVector(g.SCALE_KEY)[0]))
        return math.exp(-float(self._estimate.atVector(g.SCALE_KEY)[0]))

    def keyframe_poses(
        self, movements: Iterable[int], scale: float
    ) -> dict[tuple[int, int], KeyframePose]:
        """Both keyframes of each of ``movements`` (placed), ``(movement, end)``: position and
        heading (FL) and iSAM2's marginal covariance of ``(x, y, heading)`` times ``scale``; a
        keyframe whose marginal iSAM2 cannot give (an indeterminate system) is left out."""
        out = {}
        for k in movements:
            for end in (0, 1):
                key = g.pose_key(k, end)
                p = self.values.atPose2(key)
                try:
                    cov = np.asarray(self.isam.marginalCovariance(key), np.float64) * scale
                except RuntimeError:  # GTSAM's indeterminate linear system
                    continue
                out[k, end] = KeyframePose(
                    np.array([p.x(), p.y()]), float(p.theta()), 0.5 * (cov + cov.T)
                )
        return out

    # ------------------------------------------------------------------ bearings
    def retable(self, state: MapState) -> None:
        """The bearing table built anew from the placed movements (after a change of the map
        other than bearings added or rejected)."""
        self.table = BearingTable()
        self.table.add(state.bearings(), self.settings.index, state.rejected)

    def residuals(self) -> NDArray[np.float64]:
        """The residual (rad) of every bearing of the map (a row of the bearing table) under
        the current values; kept until the values are replaced or the table changes."""
        memo = self._residual_memo
        if memo is not None and memo[0] is self.values and memo[1] == self.table.version:
            return memo[2]
        r = self.table.residuals(self.values)
        r.setflags(write=False)  # shared by the callers until the map changes
        self._residual_memo = (self.values, self.table.version, r)  # holds the values
        return r

    def all_residuals(self, state: MapState) -> NDArray[np.float64]:
        """The residuals of the graph's bearings (:meth:`residuals`), then those of the frozen
        movements' bearings as they were when their movements left the graph."""
        frozen = state.frozen_bearings
        if not len(frozen):
            return self.residuals()
        return np.concatenate([self.residuals(), frozen.residual_rad])

    def bearing_noise(self, state: MapState) -> gtsam.noiseModel.Base:
        """The bearing factors' noise model (the model's std, Huber loss if robust)."""
        return g.bearing_noise(state.sigma_model_rad, self.settings.robust)

    def add_bearing(
        self, graph: gtsam.NonlinearFactorGraph, b: g.Bearing, noise: gtsam.noiseModel.Base
    ) -> None:
        """Add a bearing factor to ``graph``, remembering where (for its iSAM2 index)."""
        self._staged.append((graph.size(), b))
        graph.add(
            g.bearing_factor(
                g.pose_key(b.movement, b.end), self.key(b.landmark), b.bearing_rad, noise
            )
        )

    def set_rejected(
        self, state: MapState, out: Collection[g.Bearing], back: Collection[g.Bearing]
    ) -> None:
        """Take bearings ``out`` of the graph as rejected and put rejected ones ``back``, in
        one iSAM2 update."""
        graph = gtsam.NonlinearFactorGraph()
        noise = self.bearing_noise(state)
        for b in back:
            state.rejected.discard(b)
            self.add_bearing(graph, b, noise)
        remove = [self.factor_of.pop(b) for b in out]
        state.rejected.update(out)
        self.table.set_rejected(back, False)
        self.table.set_rejected(out, True)
        self.update(graph, gtsam.Values(), remove)

    # ------------------------------------------------------------------ movements
    def distance_m(self, m: Movement) -> float | None:
        """The distance the prior uses for ``m`` (None: no prior, or no usable distance)."""
        d = m.distance_m
        if (
            self.settings.distance_prior_rel is None
            or d is None
            or not (math.isfinite(d) and d > 0.0)
        ):
            return None
        return d

    def _distance_factor(self, movement: int, distance_m: float) -> gtsam.NonlinearFactor:
        return g.distance_factor(
            g.pose_key(movement, 0),
            g.pose_key(movement, 1),
            distance_m,
            self.settings.distance_prior_rel or 0.0,
            self.settings.robust,
        )

    def _link_factor(self, state: MapState, link: tuple[int, int]) -> gtsam.NonlinearFactor:
        a, b = link
        sigma = self.settings.turn_prior_sigma_rad
        turn = state.placed[b].turn_rad if sigma is not None else None
        return g.in_place_factor(g.pose_key(a, 1), g.pose_key(b, 0), turn, sigma or 0.0)

    def add_movement(
        self,
        state: MapState,
        m: Movement,
        pose: MovementPose,
        graph: gtsam.NonlinearFactorGraph,
        values: gtsam.Values,
        outliers: set[g.Bearing] | None = None,
    ) -> None:
        """Put a placed movement's poses, constraints and bearings into ``graph``/``values``
        (``outliers`` stay out, as rejected); it moves from waiting to placed in ``state``."""
        links = state.links_of(m.index)
        state.placed[m.index] = m
        state.waiting.pop(m.index, None)
        graph.add(g.straight_factor(g.pose_key(m.index, 0), g.pose_key(m.index, 1)))
        for end, p2 in enumerate(pose2s(pose)):
            key = g.pose_key(m.index, end)
            values.insert(key, p2)
            graph.add(g.weak_pose_prior(key, p2))
        distance = self.distance_m(m)
        if distance is not None:
            if not values.exists(g.SCALE_KEY) and not self.has(g.SCALE_KEY):
                log_scale = math.log(pose.length_fl / distance)
                values.insert(g.SCALE_KEY, np.array([log_scale]))
                graph.add(g.weak_scale_prior(log_scale))
            graph.add(self._distance_factor(m.index, distance))
        for link in links:
            state.links.add(link)
            graph.add(self._link_factor(state, link))
        noise = self.bearing_noise(state)
        for b in m.bearings:
            if outliers and b in outliers:
                state.rejected.add(b)
            elif b.landmark in state.in_graph:
                self.add_bearing(graph, b, noise)
            else:
                state.pending.setdefault(b.landmark, []).append(b)
        mapped = [b for b in m.bearings if b.landmark in state.in_graph]
        self.table.add(mapped, self.settings.index, outliers or ())

    # ------------------------------------------------------------------ landmarks
    def enter_pending(
        self,
        state: MapState,
        graph: gtsam.NonlinearFactorGraph,
        values: gtsam.Values,
        belief_of: Callable[[str], LandmarkEstimate | None],
    ) -> list[str]:
        """Landmarks that can enter the graph now, with their waiting bearings (initial points
        from their rays, else from the initializer's belief, ``belief_of(name)``)."""
        entered = []
        noise = self.bearing_noise(state)
        for name in sorted(state.pending, key=self.settings.index.__getitem__):
            point = self._initial_point(state, name, values, belief_of)
            if point is None:
                continue
            values.insert(self.key(name), point)
            graph.add(g.weak_point_prior(self.key(name), point))
            waiting = state.pending.pop(name)
            for bearing in waiting:
                self.add_bearing(graph, bearing, noise)
            self.table.add(waiting, self.settings.index)
            state.in_graph.add(name)
            entered.append(name)
        return entered

    def _initial_point(
        self,
        state: MapState,
        name: str,
        values: gtsam.Values,
        belief_of: Callable[[str], LandmarkEstimate | None],
    ) -> NDArray[np.float64] | None:
        """Initial value for a landmark not in the graph, from its rays or a tight belief."""
        eps = self.settings.eps_rad
        origins, dirs = [], []
        for b in state.pending.get(name, []):
            key = g.pose_key(b.movement, b.end)
            pose = values.atPose2(key) if values.exists(key) else self.pose2(key)
            origins.append((pose.x(), pose.y()))
            dirs.append(pose.theta() + b.bearing_rad)
        fix = intersect_rays(
            np.array(origins, np.float64).reshape(-1, 2), np.array(dirs), 2.0 * eps
        )
        if (
            fix is not None
            and fix.parallax_rad >= MIN_RAY_PARALLAX_EPS * eps
            and fix.rms_rad <= eps
        ):
            return fix.point_fl
        belief = belief_of(name)
        if belief is not None and widest_std(belief.cov_fl) <= TIGHT_BELIEF_FL:
            return np.asarray(belief.mean_fl, np.float64)
        return None

    # ------------------------------------------------------------------ updates
    def update(
        self,
        graph: gtsam.NonlinearFactorGraph,
        values: gtsam.Values,
        remove: Sequence[int] = (),
    ) -> None:
        """One iSAM2 update, factor indices recorded (one more relinearization step while the
        map is careful, :data:`CAREFUL_MOVEMENTS`); the estimate is computed when asked."""
        result = self.isam.update(graph, values, list(remove))
        index = result.getNewFactorsIndices()
        for pos, b in self._staged:
            self.factor_of[b] = int(index[pos])
        self._staged.clear()
        self._estimate = None
        if self.careful:
            self.isam.update()

    def full_graph(self, state: MapState, values: gtsam.Values) -> gtsam.NonlinearFactorGraph:
        """Every factor of the map (for a rebuild), weak priors at ``values``."""
        graph = gtsam.NonlinearFactorGraph()
        l1, l2 = self.settings.reference
        for f in g.gauge_factors(self.key(l1), self.key(l2)):
            graph.add(f)
        for name in state.in_graph - set(self.settings.reference):
            key = self.key(name)
            graph.add(g.weak_point_prior(key, np.asarray(values.atPoint2(key), np.float64)))
        if values.exists(g.SCALE_KEY):
            graph.add(g.weak_scale_prior(float(values.atVector(g.SCALE_KEY)[0])))
        for k in sorted(state.placed):
            graph.add(g.straight_factor(g.pose_key(k, 0), g.pose_key(k, 1)))
            for end in (0, 1):
                key = g.pose_key(k, end)
                graph.add(g.weak_pose_prior(key, values.atPose2(key)))
            distance = self.distance_m(state.placed[k])
            if distance is not None and values.exists(g.SCALE_KEY):
                graph.add(self._distance_factor(k, distance))
        for link in sorted(state.links):
            graph.add(self._link_factor(state, link))
        if state.prior is not None:
            graph.add(state.prior)
        noise = self.bearing_noise(state)
        self.factor_of.clear()
        for b in state.bearings(rejected=False):
            self.add_bearing(graph, b, noise)
        return graph

    def rebuild(self, state: MapState, values: gtsam.Values, solve: bool = True) -> None:
        """A fresh iSAM2 over every factor, from ``values`` refined by Levenberg-Marquardt
        (unless not ``solve``)."""
        graph = self.full_graph(state, values)
        # an indeterminate system keeps the initial values; iSAM2 below still solves from them
        if solve:
            with contextlib.suppress(RuntimeError):
                values = g.solve_batch(graph, values)
        self.isam = self.new_isam(len(state.placed))
        self.update(graph, values)

    def restart(
        self,
        state: MapState,
        factors: gtsam.NonlinearFactorGraph,
        bearings: Mapping[int, g.Bearing],
        values: gtsam.Values,
    ) -> None:
        """A fresh iSAM2 over ``factors`` (the factor at position ``i`` is the bearing
        ``bearings[i]``, when there is one) from ``values``, without a new solve."""
        self.factor_of.clear()
        self._staged = sorted(bearings.items())
        self.isam = self.new_isam(len(state.placed))
        self.update(factors, values)

    def restore(self, state: MapState, values: gtsam.Values) -> None:
        """The graph of ``state`` (a snapshot taken with ``values``) again: rebuilt from
        ``values``, or empty when no movement is placed."""
        self._staged.clear()
        self.factor_of.clear()
        self.retable(state)
        if state.placed:
            self.rebuild(state, values)
        else:
            self.isam, self.values = self.new_isam(len(state.placed)), gtsam.Values()

    def bootstrap(
        self,
        state: MapState,
        guesses: Mapping[int, MovementPose],
        seeds_fl: Mapping[str, NDArray[np.float64]],
    ) -> list[int] | str:
        """Start the map: one batch solve over the waiting movements ``guesses`` (their poses in
        the reference pair's frame) and the landmarks ``seeds_fl`` (first points, FL); the
        movements placed, or why not (then ``state`` is to be restored by the caller: the
        movements wait again, and the graph is left empty)."""
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        l1, l2 = self.settings.reference
        for f in g.gauge_factors(self.key(l1), self.key(l2)):
            graph.add(f)
        values.insert(self.key(l1), np.array([0.0, 0.0]))
        values.insert(self.key(l2), np.array([1.0, 0.0]))
        for name, point in seeds_fl.items():
            values.insert(self.key(name), point)
            graph.add(g.weak_point_prior(self.key(name), point))
            state.in_graph.add(name)
        for k, guess in guesses.items():
            self.add_movement(state, state.waiting[k], guess, graph, values)
        try:
            solved = g.solve_batch(graph, values)
        except RuntimeError as exc:
            solved = None
            why = f"bootstrap failed ({str(exc).strip().splitlines()[0]})"
        if solved is not None:
            self.values = solved
            r = self.residuals()
            robust = robust_std(r) if r.size else 0.0
            why = (
                f"bootstrap does not fit (robust residual {math.degrees(robust):.2f} deg > eps)"
                if robust > self.settings.eps_rad
                else ""
            )
        if why or solved is None:  # undo: the graph is empty again
            self._staged.clear()
            self.table = BearingTable()
            self.values = gtsam.Values()
            return why or "bootstrap failed"
        self.isam = self.new_isam(len(state.placed))
        self.update(graph, solved)
        return sorted(guesses)

    # ------------------------------------------------------------------ estimates
    def update_estimates(self, state: MapState) -> None:
        """The bearing noise from the residuals (the model's std re-tuned, and the graph
        rebuilt, when it is off by more than :data:`RETUNE_RATIO`) and every non-reference
        landmark's estimate: iSAM2's marginal scaled by the estimated noise."""
        s = self.settings
        r = self.all_residuals(state)
        state.noise = estimate_noise(r, state.n_params(), s.sigma0_rad, s.eps_rad)
        n = state.noise
        off = abs(math.log(n.sigma_rad / state.sigma_model_rad))
        if n.dof >= RETUNE_DOF and off > math.log(RETUNE_RATIO):
            state.sigma_model_rad = n.sigma_rad
            self.rebuild(state, self.values)
            r = self.all_residuals(state)
            state.noise = estimate_noise(r, state.n_params(), s.sigma0_rad, s.eps_rad)
        scale = state.covariance_scale()
        names = sorted(state.in_graph - set(s.reference), key=s.index.__getitem__)
        out = {}
        if names:  # one joint marginal: the landmarks share the root of the Bayes tree
            joint = self.isam.jointMarginalCovariance([self.key(n) for n in names])
            for name in names:
                key = self.key(name)
                cov = np.asarray(joint.at(key, key), np.float64) * scale
                out[name] = LandmarkEstimate(self.point(name), 0.5 * (cov + cov.T))
        state.estimates = out
