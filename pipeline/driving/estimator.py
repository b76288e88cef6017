"""A driving robot's map from odometry and bearings: keyframes in iSAM2 (docs/method.md).

:class:`DrivingSlam` takes odometry poses and bearing sets in time order. Odometry makes the
keyframes (:mod:`pipeline.driving.keyframes`). A bearing set is placed on the odometry between
its two samples and hangs on the last keyframe before it through the odometry increment from
that keyframe; of the bearings of one landmark in one keyframe's window only the first (the
nearest to the keyframe) is kept, so each keyframe adds at most one bearing per landmark.

When odometry makes keyframe ``k + 1``, one iSAM2 ``update`` adds: the new pose, the odometry
factor ``k -> k + 1`` (wheel-model noise), and the bearings of keyframe ``k``'s window. A
bearing of a mapped landmark becomes a bearing factor (Huber loss). A landmark not yet mapped
keeps its rays; it enters when the new ray and one of them cross with at least
``min_parallax_rad`` (and more than twice the bearing error bound): the impartial PDF
initializes it from those two views (:func:`pipeline.driving.two_views.initialize_two_views`),
and all its rays become factors. The first keyframe fixes the gauge (its odometry pose), the
odometry the scale (metres). The reported map is in FL (the reference pair at (0, 0) and
(1, 0)) once both reference landmarks are mapped, and its unit |L1 L2| in metres.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import gtsam
import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad
from data_schemas.errors import EstimationError
from pipeline.cones import Degenerate
from pipeline.crb import truncated_gaussian_std
from pipeline.driving.factors import (
    fixed_sensor_bearing_factor,
    gauge_factor,
    keyframe_key,
    odometry_factor,
    offset_bearing_factor,
)
from pipeline.driving.keyframes import KeyframeRule, KeyframeSelector
from pipeline.driving.lag import DEFAULT_KEYFRAME_WINDOW, drop_keyframes
from pipeline.driving.odometry import WheelNoise, between, compose, interpolate
from pipeline.driving.two_views import initialize_two_views
from pipeline.estimate import LandmarkEstimate
from pipeline.frame_change import to_fl
from pipeline.geometry import bearing_point
from pipeline.joint.graph import bearing_noise, landmark_key, weak_point_prior
from pipeline.priors import PriorName


@dataclass(frozen=True)
class DrivingOptions:
    """Settings of :class:`DrivingSlam`.

    Attributes
    ----------
    keyframes : KeyframeRule
        When odometry makes a keyframe.
    wheel : WheelNoise
        Std of the odometry between keyframes.
    min_parallax_rad : float
        Smallest angle between two rays that initializes a landmark (half of it once
        ``max_rays`` rays wait; never under twice the bearing error bound).
    r_min_m, r_max_m : float
        Range bounds (m) of the initialization's prior.
    n_particles : int
        Particles of a landmark's two-view initialization.
    prior : {"impartial", "gaussian", "mixture"}
        Single-bearing prior of the initialization.
    robust : bool
        Huber loss on the bearing factors.
    min_rays : int
        Rays of a landmark that must agree (within twice the bearing error bound) with its
        two-view initialization before it enters the map.
    max_rays : int
        Rays kept per landmark not yet mapped (the oldest go first).
    relinearize_threshold : float
        iSAM2's relinearization threshold.
    dogleg : bool
        Powell's dogleg steps in iSAM2 (else Gauss-Newton).
    window_keyframes : int or None
        Keyframes kept in iSAM2: once it holds ``window_keyframes + window_stride``, the oldest
        ``window_stride`` are marginalized into one linear prior and their poses frozen
        (None: every keyframe stays; the default bounds the cost per keyframe: docs/method.md,
        "A driving robot").
    window_stride : int
        Keyframes that leave iSAM2 at once (one rebuild of iSAM2 per this many keyframes).
    settle_keyframes : int
        A keyframe stays in iSAM2 while a landmark it sees entered the map fewer than this many
        keyframes ago (its bearings are not linearized while the landmark is still moving),
        unless iSAM2 holds ``2 * window_keyframes + window_stride`` keyframes.
    frozen_pose_noise : bool
        A bearing from a frozen keyframe gets the frozen pose's uncertainty (its marginal
        covariance when it left, propagated to the bearing) added to its own.
    """

    keyframes: KeyframeRule = field(default_factory=KeyframeRule)
    wheel: WheelNoise = field(default_factory=WheelNoise)
    min_parallax_rad: float = math.radians(15.0)
    r_min_m: float = 0.1
    r_max_m: float = 30.0
    n_particles: int = 300
    prior: PriorName = "impartial"
    robust: bool = True
    min_rays: int = 3
    max_rays: int = 40
    relinearize_threshold: float = 0.01
    dogleg: bool = True
    window_keyframes: int | None = DEFAULT_KEYFRAME_WINDOW
    window_stride: int = 25
    settle_keyframes: int = 100
    frozen_pose_noise: bool = True


@dataclass(frozen=True)
class Ray:
    """One bearing of a landmark: the keyframe it hangs on, the odometry offset from that
    keyframe to the sensor (3,: m, m, rad, body frame), the bearing and its std (rad)."""

    keyframe: int
    offset: NDArray[np.float64]
    bearing_rad: float
    sigma_rad: float


@dataclass(frozen=True)
class KeyframeResult:
    """What one keyframe added to the map (returned when the next keyframe closes it).

    Attributes
    ----------
    index : int
        Keyframe index (0, 1, ...).
    t_ns : int
        Time of its odometry sample.
    pose_m : (3,) float
        Its pose in the map frame (m, m, rad) after the update.
    next_pose_m : (3,) float
        The next keyframe's pose after the update.
    rays : dict name -> Ray
        The bearings of its window (one per landmark).
    entered : dict name -> (2,) float
        Landmarks this update initialized, their initial positions (m, map frame).
    waiting : dict name -> str
        Landmarks seen here and not yet mapped, with why.
    """

    index: int
    t_ns: int
    pose_m: NDArray[np.float64]
    next_pose_m: NDArray[np.float64]
    rays: dict[str, Ray]
    entered: dict[str, NDArray[np.float64]]
    waiting: dict[str, str]


def _ray_world(pose: NDArray[np.float64], ray: Ray) -> tuple[NDArray[np.float64], float]:
    """The sensor pose (3,) of a ray given its keyframe's pose, and the ray's direction (rad)."""
    sensor = compose(pose, ray.offset)
    return sensor, float(sensor[2]) + ray.bearing_rad


#: Rounds of "keep the rays that agree with the point, fit the point to them" at entry.
REFINE_ROUNDS = 3


def _ray_error(
    point_m: NDArray[np.float64], sensor: NDArray[np.float64], direction: float
) -> float:
    """Angle (rad) between a ray (sensor pose (3,), direction) and the direction to a point."""
    to = math.atan2(point_m[1] - sensor[1], point_m[0] - sensor[0])
    return abs(float(wrap_rad(to - direction)))


class DrivingSlam:
    """The driving robot's map (see the module doc).

    Parameters
    ----------
    landmarks : sequence of str
        Catalog names (their order gives the landmark keys).
    reference : (str, str)
        The reference pair L1, L2 of the reported map.
    vision_error_rad : float
        Bound ``eps`` on a bearing's error; a bearing without its own std gets the std of the
        Gaussian truncated at ``eps`` (:func:`pipeline.crb.truncated_gaussian_std`).
    rng : numpy.random.Generator
    options : DrivingOptions
    """

    def __init__(
        self,
        landmarks: Sequence[str],
        reference: tuple[str, str],
        *,
        vision_error_rad: float,
        rng: np.random.Generator,
        options: DrivingOptions | None = None,
    ) -> None:
        self.names = list(landmarks)
        self.index = {n: i for i, n in enumerate(self.names)}
        if reference[0] not in self.index or reference[1] not in self.index:
            raise EstimationError(f"reference pair {reference} is not in the landmark catalog")
        self.reference = reference
        self.eps_rad = vision_error_rad
        self.sigma0_rad = truncated_gaussian_std(vision_error_rad)
        self.rng = rng
        self.options = options or DrivingOptions()
        o = self.options
        if (o.window_keyframes is not None and o.window_keyframes < 1) or o.window_stride < 1:
            raise EstimationError(
                f"window of {o.window_keyframes} keyframes, stride {o.window_stride}: "
                "both must be at least 1 (or the window None: every keyframe)"
            )
        params = gtsam.ISAM2Params()
        params.setRelinearizeThreshold(self.options.relinearize_threshold)
        params.relinearizeSkip = 1
        if self.options.dogleg:
            params.setOptimizationParams(gtsam.ISAM2DoglegParams())
        self._params = params
        self.isam = gtsam.ISAM2(params)
        self.selector = KeyframeSelector(self.options.keyframes)
        #: every factor of the problem (also those iSAM2 has marginalized or never got), for a
        #: batch solve of it
        self.graph = gtsam.NonlinearFactorGraph()
        self._new = gtsam.NonlinearFactorGraph()
        self._new_values = gtsam.Values()
        self._from_frozen = gtsam.NonlinearFactorGraph()  # bearings from frozen keyframes
        self._keyframes: list[tuple[int, NDArray[np.float64]]] = []  # (t_ns, odometry pose)
        #: poses (3,) of the keyframes 0, 1, ... that left iSAM2, as they were when they left
        self.frozen: list[NDArray[np.float64]] = []
        #: frozen keyframe -> its pose's covariance (3, 3) (local frame) when it left (those
        #: holding bearings of landmarks not yet mapped)
        self._frozen_cov: dict[int, NDArray[np.float64]] = {}
        #: bearings of landmarks entering late that hang on a frozen keyframe: in iSAM2 from
        #: the keyframe's frozen pose, on the landmark alone
        self.frozen_rays = 0
        self._window: dict[str, Ray] = {}
        self._prev: tuple[int, NDArray[np.float64]] | None = None  # last odometry sample
        self._waiting_bearings: list[tuple[int, dict[str, float], dict[str, float]]] = []
        self._rays: dict[str, list[Ray]] = {}
        self.mapped: set[str] = set()
        #: landmark -> (keyframe it entered at, first keyframe of its bearings in iSAM2)
        self._entered: dict[str, tuple[int, int]] = {}
        self._noise: dict[float, gtsam.noiseModel.Base] = {}
        self._finished = False

    # ---- input -------------------------------------------------------------------------

    def odometry(self, t_ns: int, pose: NDArray[np.float64]) -> list[KeyframeResult]:
        """One odometry pose (3,) (m, m, rad, odometry frame) at ``t_ns``; the keyframe it
        closes, if it makes a new one."""
        pose = np.asarray(pose, np.float64)
        if not np.all(np.isfinite(pose)):
            raise EstimationError(f"odometry pose at t = {t_ns} ns is not finite: {pose}")
        if self._prev is not None and t_ns < self._prev[0]:
            raise EstimationError(
                f"odometry goes back in time ({t_ns} ns after {self._prev[0]} ns)"
            )
        # bearings before this sample belong to the window that is open now
        self._resolve(t_ns, pose, before=True)
        out: list[KeyframeResult] = []
        if self.selector.add(pose):
            out += self._new_keyframe(t_ns, pose)
        self._prev = (t_ns, pose)
        self._resolve(t_ns, pose, before=False)
        return out

    def bearings(
        self,
        t_ns: int,
        bearings_rad: Mapping[str, float],
        std_rad: Mapping[str, float] | None = None,
    ) -> None:
        """Bearings (rad, relative to the heading) of landmarks at ``t_ns``, with their stds
        where known; names outside the catalog are ignored."""
        known = {n: float(b) for n, b in bearings_rad.items() if n in self.index}
        if not known:
            return
        self._waiting_bearings.append((t_ns, known, dict(std_rad or {})))
        if self._prev is not None and t_ns <= self._prev[0]:
            self._resolve(self._prev[0], self._prev[1], before=False)

    def finish(self) -> list[KeyframeResult]:
        """Close the last keyframe: its bearings enter the map (at the end; once)."""
        if not self._keyframes or self._finished:
            return []
        self._finished = True
        if self._prev is not None:
            self._resolve(self._prev[0] + 1, self._prev[1], before=True)
        return self._close(None)

    # ---- keyframes ---------------------------------------------------------------------

    def _resolve(self, t_ns: int, pose: NDArray[np.float64], *, before: bool) -> None:
        """Place the waiting bearings with times before (or at) ``t_ns`` on the odometry."""
        if not self._keyframes:
            return
        keep = []
        for item in self._waiting_bearings:
            t_b = item[0]
            if (t_b < t_ns) if before else (t_b <= t_ns):
                prev = self._prev or (t_ns, pose)
                at = interpolate(t_b, prev[0], prev[1], t_ns, pose)
                self._add_to_window(at, item[1], item[2])
            else:
                keep.append(item)
        self._waiting_bearings = keep

    def _add_to_window(
        self, odom_pose: NDArray[np.float64], bearings: dict[str, float], stds: dict[str, float]
    ) -> None:
        k = len(self._keyframes) - 1
        offset = between(self._keyframes[k][1], odom_pose)
        for name, b in bearings.items():
            if name in self._window:
                continue
            sigma = float(stds.get(name, self.sigma0_rad))
            self._window[name] = Ray(k, offset, float(wrap_rad(b)), sigma)

    def _new_keyframe(self, t_ns: int, pose: NDArray[np.float64]) -> list[KeyframeResult]:
        k = len(self._keyframes)
        if k == 0:
            self._keyframes.append((t_ns, pose))
            self._new.push_back(gauge_factor(pose))
            self._new_values.insert(keyframe_key(0), gtsam.Pose2(*pose))
            return []
        prev_pose = self._keyframes[k - 1][1]
        delta = between(prev_pose, pose)
        path_m, turn_rad = self.selector.segment
        self._keyframes.append((t_ns, pose))
        self._new.push_back(
            odometry_factor(k - 1, k, delta, self.options.wheel.sigmas(path_m, turn_rad))
        )
        guess = compose(self.pose_m(k - 1), delta)
        self._new_values.insert(keyframe_key(k), gtsam.Pose2(*guess))
        return self._close(k)

    def _close(self, new_k: int | None) -> list[KeyframeResult]:
        """Enter the open window's bearings and run one iSAM2 update."""
        k = len(self._keyframes) - 1 if new_k is None else new_k - 1
        rays, self._window = self._window, {}
        entered: dict[str, NDArray[np.float64]] = {}
        waiting: dict[str, str] = {}
        for name, ray in rays.items():
            if name in self.mapped:
                self._bearing(name, ray)
                continue
            got = self._try_enter(name, ray)
            if isinstance(got, str):
                waiting[name] = got
            else:
                entered[name] = got
        self.graph.push_back(self._new)
        self._new.push_back(self._from_frozen)
        self.isam.update(self._new, self._new_values)
        self._from_frozen = gtsam.NonlinearFactorGraph()
        self._new = gtsam.NonlinearFactorGraph()
        self._new_values = gtsam.Values()
        self._slide()
        last = len(self._keyframes) - 1
        return [
            KeyframeResult(
                k,
                self._keyframes[k][0],
                self.pose_m(k),
                self.pose_m(last),
                rays,
                entered,
                waiting,
            )
        ]

    def _slide(self) -> None:
        """Marginalize the oldest keyframes once iSAM2 holds the window and its stride: at least
        a stride of them, none from the first keyframe of a landmark younger than
        ``settle_keyframes`` on (unless iSAM2 holds twice the window and the stride)."""
        window, stride = self.options.window_keyframes, self.options.window_stride
        if window is None or len(self._keyframes) - len(self.frozen) < window + stride:
            return
        last = len(self._keyframes) - 1
        end = len(self._keyframes) - window
        if len(self._keyframes) - len(self.frozen) < 2 * window + stride:
            for at, first in self._entered.values():
                if at > last - self.options.settle_keyframes:
                    end = min(end, first)
            if end - len(self.frozen) < stride:
                return
        old = range(len(self.frozen), end)
        if self.options.frozen_pose_noise:
            waiting = {r.keyframe for rays in self._rays.values() for r in rays}
            for k in waiting.intersection(old):
                self._frozen_cov[k] = np.asarray(self.isam.marginalCovariance(keyframe_key(k)))
        self.isam, values = drop_keyframes(self.isam, self._params, [keyframe_key(k) for k in old])
        for k in old:
            p = values.atPose2(keyframe_key(k))
            self.frozen.append(np.array([p.x(), p.y(), p.theta()]))

    def _bearing(self, name: str, ray: Ray) -> None:
        noise = self._noise.get(ray.sigma_rad)
        if noise is None:
            noise = self._noise[ray.sigma_rad] = bearing_noise(ray.sigma_rad, self.options.robust)
        factor = offset_bearing_factor(
            keyframe_key(ray.keyframe),
            landmark_key(self.index[name]),
            ray.bearing_rad,
            ray.offset,
            noise,
        )
        if ray.keyframe < len(self.frozen):  # its keyframe left iSAM2: seen from a fixed pose
            self.frozen_rays += 1
            self.graph.push_back(factor)
            sensor = compose(self.frozen[ray.keyframe], ray.offset)
            if ray.keyframe in self._frozen_cov:
                noise = self._frozen_noise(name, ray)
            factor = fixed_sensor_bearing_factor(
                landmark_key(self.index[name]), sensor, ray.bearing_rad, noise
            )
            self._from_frozen.push_back(factor)
        else:
            self._new.push_back(factor)

    def _frozen_noise(self, name: str, ray: Ray) -> gtsam.noiseModel.Base:
        """The noise of ``ray`` (on a frozen keyframe) with its frozen pose's covariance
        propagated to the bearing (numeric Jacobian at the landmark's entry point)."""
        key = landmark_key(self.index[name])
        if self._new_values.exists(key):
            pt = np.asarray(self._new_values.atPoint2(key))
        else:
            pt = np.asarray(self.isam.calculateEstimatePoint2(key))
        pose = self.frozen[ray.keyframe]

        def bearing(d: NDArray[np.float64]) -> float:
            s = compose(compose(pose, d), ray.offset)
            return math.atan2(float(pt[1] - s[1]), float(pt[0] - s[0])) - float(s[2])

        h, at = 1e-6, bearing(np.zeros(3))
        jac = np.array([float(wrap_rad(bearing(h * e) - at)) / h for e in np.eye(3)])
        var = ray.sigma_rad**2 + float(jac @ self._frozen_cov[ray.keyframe] @ jac)
        return bearing_noise(math.sqrt(var), self.options.robust)

    def _try_enter(self, name: str, ray: Ray) -> NDArray[np.float64] | str:
        """Initialize ``name`` from its new ray and the earlier one that crosses it widest."""
        earlier = self._rays.setdefault(name, [])
        sensor, direction = _ray_world(self.pose_m(ray.keyframe), ray)
        best: tuple[float, NDArray[np.float64], Ray] | None = None
        for old in earlier:
            old_sensor, old_dir = _ray_world(self.pose_m(old.keyframe), old)
            parallax = abs(float(wrap_rad(direction - old_dir)))
            if best is None or parallax > best[0]:
                best = (parallax, old_sensor, old)
        earlier.append(ray)
        del earlier[: -self.options.max_rays]
        if best is None:
            return "one ray so far"
        # a landmark seen from max_rays keyframes without the parallax (far, or on the line
        # of motion) may enter with half of it: its many rays decide its range
        patient = len(earlier) >= self.options.max_rays
        need = self.options.min_parallax_rad * (0.5 if patient else 1.0)
        need = max(need, 2.0 * self.eps_rad)
        if best[0] < need:
            return f"widest parallax {math.degrees(best[0]):.1f} deg < {math.degrees(need):.1f}"
        o = self.options
        particles = initialize_two_views(
            best[1],
            best[2].bearing_rad,
            sensor,
            ray.bearing_rad,
            eps_rad=self.eps_rad,
            r_min_m=o.r_min_m,
            r_max_m=o.r_max_m,
            n=o.n_particles,
            rng=self.rng,
            prior=o.prior,
        )
        if isinstance(particles, Degenerate):
            return particles.reason
        point = particles.mean(axis=0)
        sensors = [_ray_world(self.pose_m(r.keyframe), r) for r in earlier]
        for _ in range(REFINE_ROUNDS):  # the rays that agree with the point decide it
            agree = [
                i for i, sd in enumerate(sensors) if _ray_error(point, *sd) <= 2 * self.eps_rad
            ]
            if len(agree) < o.min_rays:
                return f"{len(agree)} of {len(earlier)} rays agree with the two views' point"
            point = bearing_point(
                np.array([sensors[i][0][:2] for i in agree], np.float64),
                np.array([sensors[i][1] for i in agree], np.float64),
                point,
            )
            reach = min(float(np.hypot(*(point - sd[0][:2]))) for sd in sensors)
            if not reach <= o.r_max_m:  # nearly parallel rays: no point to trust
                return f"the rays meet farther than r_max = {o.r_max_m:g} m"
        agree = [i for i, sd in enumerate(sensors) if _ray_error(point, *sd) <= 2 * self.eps_rad]
        if len(agree) < o.min_rays:
            return f"{len(agree)} of {len(earlier)} rays agree with the rays' point"
        key = landmark_key(self.index[name])
        self._new_values.insert(key, point)
        self._new.push_back(weak_point_prior(key, point))
        self.mapped.add(name)
        del self._rays[name]
        for i in agree:  # the others are taken for wrong detections
            self._bearing(name, earlier[i])
        self._entered[name] = (ray.keyframe, min(earlier[i].keyframe for i in agree))
        return np.asarray(point, np.float64)

    # ---- the map -----------------------------------------------------------------------

    @property
    def n_keyframes(self) -> int:
        """Keyframes made so far."""
        return len(self._keyframes)

    @property
    def keyframe_times_ns(self) -> list[int]:
        """Each keyframe's odometry time (ns)."""
        return [t for t, _ in self._keyframes]

    def pose_m(self, k: int) -> NDArray[np.float64]:
        """Keyframe ``k``'s pose (3,) (m, m, rad, map frame): the current estimate (a frozen
        keyframe's: its estimate when it left iSAM2)."""
        if k < len(self.frozen):
            return self.frozen[k].copy()
        key = keyframe_key(k)
        if self._new_values.exists(key):
            p = self._new_values.atPose2(key)
        else:
            p = self.isam.calculateEstimatePose2(key)
        return np.array([p.x(), p.y(), p.theta()])

    def landmarks_m(self) -> dict[str, NDArray[np.float64]]:
        """Mapped landmarks (2,) in the map frame (m), catalog order."""
        return {
            n: np.asarray(self.isam.calculateEstimatePoint2(landmark_key(self.index[n])))
            for n in self.names
            if n in self.mapped and not self._new_values.exists(landmark_key(self.index[n]))
        }

    def trajectory_m(self) -> NDArray[np.float64]:
        """Every keyframe's pose (k, 3) (m, m, rad, map frame)."""
        return np.array([self.pose_m(k) for k in range(len(self._keyframes))]).reshape(-1, 3)

    @property
    def unit_m(self) -> float | None:
        """|L1 L2| (m), once both reference landmarks are mapped."""
        pts = self.landmarks_m()
        l1, l2 = self.reference
        if l1 not in pts or l2 not in pts:
            return None
        return float(np.hypot(*(pts[l2] - pts[l1])))

    def to_fl(self, points_m: NDArray[np.float64]) -> NDArray[np.float64] | None:
        """Points (..., 2) of the map frame (m) in FL, once both reference landmarks are mapped."""
        pts = self.landmarks_m()
        l1, l2 = self.reference
        if l1 not in pts or l2 not in pts:
            return None
        return to_fl(np.asarray(points_m, np.float64), pts[l1], pts[l2])

    def estimates(self, *, covariance: bool = False) -> dict[str, LandmarkEstimate]:
        """The map in FL: every mapped non-reference landmark (empty until both reference
        landmarks are mapped). ``covariance``: iSAM2's marginal of each landmark (m^2), sent
        to FL with the map's similarity (the reference pair taken as exact); otherwise zero."""
        pts = self.landmarks_m()
        l1, l2 = self.reference
        if l1 not in pts or l2 not in pts:
            return {}
        d = pts[l2] - pts[l1]
        scale2 = float(d @ d)
        rot = np.array([[d[0], d[1]], [-d[1], d[0]]]) / scale2  # d FL / d map (m)
        out = {}
        for name, p in pts.items():
            if name in self.reference:
                continue
            cov = np.zeros((2, 2))
            if covariance:
                cov_m = self.isam.marginalCovariance(landmark_key(self.index[name]))
                cov = rot @ cov_m @ rot.T
            out[name] = LandmarkEstimate(to_fl(p, pts[l1], pts[l2]), cov)
        return out
