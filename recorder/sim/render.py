"""Render simulated panoramic frames of a :class:`~recorder.sim.world.SimWorld`.

:func:`render_panorama` draws what the robot's panoramic camera sees from its true pose, for
the camera models of :mod:`data_schemas.calibration`:

* ``unwrapped``: each landmark is a vertical bar centred on the column of its (noisy) bearing,
  spanning its angular width; its top and bottom are the cylinder's top and foot seen from a
  camera :data:`CAMERA_HEIGHT_M` above the floor, so nearer landmarks are taller. Rows map
  linearly to elevation, from :data:`ELEVATION_MAX_RAD` (row 0) to :data:`ELEVATION_MIN_RAD`.
* ``omni``: each landmark is a wedge of the ring between ``r_min`` and ``r_max``; radius maps
  linearly to elevation (``r_min`` = lowest). Inside ``r_min`` is the dark robot body, outside
  ``r_max`` black.
* ``pinhole``: a level camera; every pixel's ray (through the lens distortion, inverted by
  :mod:`recorder.sim.lens`) has a bearing and an elevation, and each landmark covers the pixels
  whose bearing lies within its angular width and whose elevation lies between its foot and
  top, with the same anti-aliasing, the kernel scaled by the local bearing and elevation step
  of one pixel. Landmarks outside the field of view are not drawn.

A coded landmark's bands (equal heights on the cylinder, top to bottom) are painted one above
the other, each at the elevations of its heights: top band at the top rows (unwrapped), at the
outer end of its wedge (omni).

Anti-aliasing: a landmark's coverage of a pixel is the integral of its footprint against a
tent (linear B-spline) kernel one pixel wide, which reproduces linear functions on the pixel
grid. Hence the coverage-weighted mean column of an unwrapped bar is exactly its centre, and the
coverage-weighted circular mean bearing of an omni wedge is its bisector to a few thousandths of
a degree. Landmarks are painted far to near, so nearer ones occlude farther ones; a bar that
straddles the panorama seam wraps around.

Noise: each bearing gets Gaussian noise (std ``bearing_noise_rad``) truncated at the vision error
bound ``vision_error_rad`` (|noise| <= eps always; the std after truncation is
:func:`data_schemas.angles.truncated_normal_std`). Frames then get lighting variation (a random
global gain and a smooth gradient toward a fixed world direction) and pixel noise (mostly luminance,
a quarter of it per channel) drawn at a random offset from a Gaussian table precomputed per image
size (so it costs one add; it is independent within a frame, not between frames). The background
(floor, walls, room) stays unsaturated grey-brown so it never looks like a landmark colour.

Speed: tables (background, pixel bearings, noise) are cached per calibration; a 255x176 frame
renders in a few hundred microseconds.

Public API
----------
:func:`render_panorama` -> :class:`RenderedFrame` (``image_bgr`` and ``truth``, one
:class:`LandmarkTruth` per landmark), :class:`Lighting`, :class:`Backdrop` (floor and wall
colours), :func:`truncated_normal`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import TWO_PI, wrap_rad
from data_schemas.calibration import (
    Calibration,
    OmniCalibration,
    PinholeCalibration,
    UnwrappedCalibration,
)
from data_schemas.colors import NOMINAL_BGR
from recorder.sim.lens import rays_of_pixels
from recorder.sim.world import Pose, SimWorld

#: Height of the camera's optical centre above the floor, m.
CAMERA_HEIGHT_M = 0.06
#: Elevation seen at the top row (unwrapped) / at ``r_max`` (omni), rad.
ELEVATION_MAX_RAD = math.radians(30.0)
#: Elevation seen at the bottom row (unwrapped) / at ``r_min`` (omni), rad.
ELEVATION_MIN_RAD = math.radians(-40.0)

# Background colours (B, G, R) by elevation band: floor, arena wall, room. All unsaturated.
_FLOOR_BGR = (100.0, 108.0, 116.0)
_WALL_BGR = (150.0, 157.0, 163.0)
_ROOM_BGR = (172.0, 172.0, 168.0)
_BODY_BGR = (45.0, 45.0, 48.0)  # omni: the robot itself, inside r_min
_OUTSIDE_BGR = (12.0, 12.0, 12.0)  # omni: outside the mirror
_WALL_BAND_RAD = (math.radians(-9.0), math.radians(5.0))
_TEXTURE_SEED = 20070101  # fixed: the background texture is part of the simulated world


@dataclass(frozen=True)
class Lighting:
    """Per-frame lighting variation.

    Attributes
    ----------
    gain_jitter : float
        The global gain is drawn uniformly in ``[1 - gain_jitter, 1 + gain_jitter]``.
    gradient : float
        Relative amplitude of a smooth brightness gradient across the panorama.
    direction_rad : float
        World direction (rad) the brighter side faces.
    """

    gain_jitter: float = 0.12
    gradient: float = 0.10
    direction_rad: float = 0.7


@dataclass(frozen=True)
class Backdrop:
    """Colours (B, G, R) of the floor and the arena wall, instead of the default unsaturated
    ones: a scene whose floor or wall looks like a landmark colour (for tests of colour under
    real light)."""

    floor_bgr: tuple[float, float, float] = _FLOOR_BGR
    wall_bgr: tuple[float, float, float] = _WALL_BGR


@dataclass(frozen=True)
class LandmarkTruth:
    """What the renderer drew for one landmark.

    Attributes
    ----------
    name : str
    color : str
        The landmark's class: its colour, or its band code (``"magenta-yellow"``).
    bearing_true_rad : float
        True bearing of the cylinder's centre, robot frame, [-pi, pi).
    bearing_drawn_rad : float
        Bearing actually drawn: true + truncated noise, [-pi, pi).
    range_m : float
        Distance from the robot to the cylinder's centre.
    half_width_rad : float
        Angular half-width of the cylinder.
    occluded_fraction : float
        Fraction of its angular extent hidden by nearer landmarks (0..1).
    visible : bool
        Drawn in the image and not fully hidden.
    """

    name: str
    color: str
    bearing_true_rad: float
    bearing_drawn_rad: float
    range_m: float
    half_width_rad: float
    occluded_fraction: float
    visible: bool


@dataclass(frozen=True, eq=False)
class RenderedFrame:
    """A rendered frame: ``image_bgr`` (H, W, 3) uint8 and one truth record per landmark."""

    image_bgr: NDArray[np.uint8]
    truth: tuple[LandmarkTruth, ...]

    def landmark(self, name: str) -> LandmarkTruth:
        """Truth of the landmark called ``name`` (KeyError if absent)."""
        for t in self.truth:
            if t.name == name:
                return t
        raise KeyError(name)


def truncated_normal(
    rng: np.random.Generator, std: float, bound: float, size: int
) -> NDArray[np.float64]:
    """Draw ``size`` values of N(0, std^2) conditioned on ``|x| <= bound`` (rejection).

    ``std == 0`` gives zeros. ``bound`` must be positive.
    """
    if bound <= 0:
        raise ValueError(f"truncation bound must be positive, got {bound}")
    if std <= 0:
        return np.zeros(size)
    out = rng.normal(0.0, std, size)
    bad = np.abs(out) > bound
    while bad.any():
        out[bad] = rng.normal(0.0, std, int(bad.sum()))
        bad = np.abs(out) > bound
    return out


def render_panorama(
    pose_world: Pose,
    world: SimWorld,
    calibration: Calibration,
    rng: np.random.Generator,
    *,
    bearing_noise_rad: float,
    vision_error_rad: float,
    pixel_noise: float = 2.0,
    lighting: Lighting | None = None,
    backdrop: Backdrop | None = None,
) -> RenderedFrame:
    """Render the panoramic frame seen from ``pose_world``.

    Parameters
    ----------
    pose_world : (x, y, heading)
        True robot pose, world frame (m, m, rad).
    world : SimWorld
        Arena and landmarks.
    calibration : UnwrappedCalibration, OmniCalibration or PinholeCalibration
        Camera model and image size.
    rng : numpy.random.Generator
        Source of bearing noise, lighting and pixel noise.
    bearing_noise_rad : float
        Std of the Gaussian bearing noise (0 = none).
    vision_error_rad : float
        Truncation bound eps of the bearing noise (> 0).
    pixel_noise : float
        Std of the pixel noise, grey levels (0 = none).
    lighting : Lighting or None
        Lighting variation; None = constant lighting.
    backdrop : Backdrop or None
        Floor and wall colours; None = the default unsaturated ones.

    Returns
    -------
    RenderedFrame
    """
    tables = _tables(calibration, backdrop or Backdrop())
    n = len(world.landmarks)
    true_rad = world.bearings_rad(pose_world)
    range_m = world.ranges_m(pose_world)
    half_rad = world.half_widths_rad(pose_world)
    occluded = world.occluded_fractions(pose_world)
    drawn_rad = wrap_rad(true_rad + truncated_normal(rng, bearing_noise_rad, vision_error_rad, n))

    image = tables.background.copy()
    surface_m = np.maximum(range_m - world.radius_m, 1e-3)
    heights = np.array([lm.height_m for lm in world.landmarks])
    elev_top = np.arctan2(heights - CAMERA_HEIGHT_M, surface_m)
    elev_bot = np.arctan2(-CAMERA_HEIGHT_M, surface_m)
    in_view = (elev_top > ELEVATION_MIN_RAD) & (elev_bot < ELEVATION_MAX_RAD) & (half_rad > 0)
    if isinstance(tables, _PinholeTables):
        rel = np.abs(wrap_rad(drawn_rad - tables.offset_rad))
        in_view = (
            (elev_top > tables.elevation_lo)
            & (elev_bot < tables.elevation_hi)
            & (half_rad > 0)
            & (rel - half_rad < tables.half_view_rad)
        )
    for i in np.argsort(-range_m):
        if not in_view[i]:
            continue
        colors = world.landmarks[i].paint
        # band k (0 = top) spans heights [(n-k-1)/n, (n-k)/n] of the cylinder
        z_m = heights[i] * np.arange(len(colors), -1, -1) / len(colors)
        elev = np.arctan2(z_m - CAMERA_HEIGHT_M, surface_m[i])
        elev[0], elev[-1] = elev_top[i], elev_bot[i]
        for k, name in enumerate(colors):
            color = np.array(NOMINAL_BGR[name], np.float32)
            lo, hi = _elevation_span(float(elev[k + 1]), float(elev[k]))
            bearing, half = float(drawn_rad[i]), float(half_rad[i])
            if isinstance(calibration, UnwrappedCalibration):
                _paint_bar(image, calibration, bearing, half, lo, hi, color)
            elif isinstance(tables, _PinholeTables):
                lo, hi = float(elev[k + 1]), float(elev[k])
                _paint_rect(image, tables, bearing, half, lo, hi, color)
            else:
                assert isinstance(tables, _OmniTables)
                _paint_wedge(image, tables, bearing, half, lo, hi, color)

    if lighting is not None:
        gain = 1.0 + rng.uniform(-lighting.gain_jitter, lighting.gain_jitter)
        phase = pose_world[2] - lighting.direction_rad
        # cos(bearing + phase) from the cached cos/sin tables
        c, s = np.float32(math.cos(phase)), np.float32(math.sin(phase))
        grad = tables.cos_bearing * c - tables.sin_bearing * s
        grad *= np.float32(gain * lighting.gradient)
        grad += np.float32(gain)
        rows = image.reshape(calibration.height, -1)
        rows *= grad
    if pixel_noise > 0:
        n_px = calibration.width * calibration.height
        start = 3 * int(rng.integers(0, tables.noise.size // 3 - n_px + 1))
        image += tables.noise[start : start + 3 * n_px].reshape(image.shape) * np.float32(
            pixel_noise
        )
    np.clip(image, 0.0, 255.0, out=image)
    image_bgr = np.asarray(cv2.convertScaleAbs(image), np.uint8)  # rounds; input is >= 0

    truth = tuple(
        LandmarkTruth(
            lm.name,
            lm.label,
            float(true_rad[i]),
            float(drawn_rad[i]),
            float(range_m[i]),
            float(half_rad[i]),
            float(occluded[i]),
            bool(in_view[i] and occluded[i] < 1.0),
        )
        for i, lm in enumerate(world.landmarks)
    )
    return RenderedFrame(image_bgr, truth)


# ------------------------------------------------------------------------------ kernels


def _tent_cdf(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """CDF of the tent (triangular) density on [-1, 1]."""
    x = np.clip(x, -1.0, 1.0)
    out: NDArray[np.float64] = 0.5 + x - 0.5 * x * np.abs(x)
    return out


def _box_spline_cdf(
    d: NDArray[np.float64], a: NDArray[np.float64], b: NDArray[np.float64]
) -> NDArray[np.float64]:
    """CDF at ``d`` of ``a (U1 + U2) + b (U3 + U4)``, ``Ui ~ U(-1/2, 1/2)`` (a, b > 0).

    This is the fraction of the 2-D tent kernel (a pixel's bilinear footprint) on one side of a
    straight edge at signed distance ``d`` whose normal is ``(a, b)`` (absolute components).
    """
    s = np.clip(d, -(a + b), a + b) + a + b
    acc = np.zeros_like(s)
    t = np.empty_like(s)
    for i, ci in ((0, 1.0), (1, -2.0), (2, 1.0)):
        for k, ck in ((0, 1.0), (1, -2.0), (2, 1.0)):
            np.subtract(s, i * a + k * b, out=t)
            np.maximum(t, 0.0, out=t)
            t *= t
            t *= t
            t *= ci * ck
            acc += t
    acc /= 24.0 * a * a * b * b
    out: NDArray[np.float64] = np.clip(acc, 0.0, 1.0, out=acc)
    return out


def _edge_cover(
    d: NDArray[np.float64], a: NDArray[np.float64], b: NDArray[np.float64]
) -> NDArray[np.float64]:
    """:func:`_box_spline_cdf`, evaluated only where the kernel straddles the edge."""
    out = (d > 0.0).astype(np.float64)
    near = np.flatnonzero(np.abs(d) < a + b)
    out[near] = _box_spline_cdf(d[near], a[near], b[near])
    return out


def _elevation_span(elev_bot: float, elev_top: float) -> tuple[float, float]:
    """Fractions (0 = lowest elevation of the image, 1 = highest) of a landmark's foot and top."""
    full = ELEVATION_MAX_RAD - ELEVATION_MIN_RAD
    return (elev_bot - ELEVATION_MIN_RAD) / full, (elev_top - ELEVATION_MIN_RAD) / full


# ------------------------------------------------------------------------------ painting


def _paint_bar(
    image: NDArray[np.float32],
    cal: UnwrappedCalibration,
    bearing_rad: float,
    half_rad: float,
    lo: float,
    hi: float,
    color: NDArray[np.float32],
) -> None:
    """Alpha-blend a vertical bar into an unwrapped panorama (in place)."""
    w, h = cal.width, cal.height
    centre = float(cal.column_of_bearing(bearing_rad))
    half_px = min(half_rad * w / TWO_PI, w / 2 - 3)
    u_lo, u_hi = centre - half_px, centre + half_px
    cols = np.arange(math.floor(u_lo) - 1, math.ceil(u_hi) + 2)
    c = cols.astype(np.float64) + 0.5
    col_cov = _tent_cdf(u_hi - c) - _tent_cdf(u_lo - c)
    # rows: elevation fraction 1 at row 0, 0 at row h; extend past the border so edges stay full
    v_top = -1.0 if hi >= 1.0 else (1.0 - hi) * h
    v_bot = h + 1.0 if lo <= 0.0 else (1.0 - lo) * h
    r0, r1 = max(math.floor(v_top) - 1, 0), min(math.ceil(v_bot) + 1, h - 1)
    if r1 < r0:
        return
    r = np.arange(r0, r1 + 1, dtype=np.float64) + 0.5
    row_cov = _tent_cdf(v_bot - r) - _tent_cdf(v_top - r)
    alpha = (row_cov[:, None] * col_cov[None, :]).astype(np.float32)[..., None]
    if cols[0] >= 0 and cols[-1] < w:  # no wrap: blend in place through a view
        block = image[r0 : r1 + 1, cols[0] : cols[-1] + 1]
        block += alpha * (color - block)
        return
    idx = cols % w
    block = image[r0 : r1 + 1, idx]
    block += alpha * (color - block)
    image[r0 : r1 + 1, idx] = block


def _paint_wedge(
    image: NDArray[np.float32],
    tables: _OmniTables,
    bearing_rad: float,
    half_rad: float,
    lo: float,
    hi: float,
    color: NDArray[np.float32],
) -> None:
    """Alpha-blend a ring wedge into an omni image (in place)."""
    b_lo, b_hi = bearing_rad - half_rad, bearing_rad + half_rad
    sel = tables.window(b_lo - tables.margin_rad, b_hi + tables.margin_rad)
    if sel.size == 0:
        return
    b = tables.bearing[sel]
    r = tables.radius[sel]
    ka, kb = tables.kernel_a[sel], tables.kernel_b[sel]
    ang_cov = _edge_cover(r * np.sin(wrap_rad(b - b_lo)), ka, kb)
    ang_cov += _edge_cover(r * np.sin(wrap_rad(b_hi - b)), ka, kb)
    ang_cov -= 1.0
    np.clip(ang_cov, 0.0, 1.0, out=ang_cov)
    # past the ring's edges the wedge runs on, so that the ring's edge rows stay fully covered
    r_bot = tables.r_min - 1.0 if lo <= 0.0 else tables.r_min + lo * (tables.r_max - tables.r_min)
    r_top = tables.r_max + 1.0 if hi >= 1.0 else tables.r_min + hi * (tables.r_max - tables.r_min)
    rad_cov = _tent_cdf(r_top - r) - _tent_cdf(r_bot - r)
    alpha = (ang_cov * rad_cov).astype(np.float32)[:, None]
    keep = alpha[:, 0] > 0
    pix = tables.pixel[sel[keep]]
    flat = image.reshape(-1, 3)
    vals = flat[pix]
    vals += alpha[keep] * (color - vals)
    flat[pix] = vals


def _paint_rect(
    image: NDArray[np.float32],
    tables: _PinholeTables,
    bearing_rad: float,
    half_rad: float,
    elev_lo_rad: float,
    elev_hi_rad: float,
    color: NDArray[np.float32],
) -> None:
    """Alpha-blend the pixels whose rays fall in a bearing x elevation box (pinhole, in place)."""
    rel = float(wrap_rad(bearing_rad - tables.offset_rad))
    b_lo, b_hi = rel - half_rad, rel + half_rad
    cols = np.flatnonzero((tables.col_max >= b_lo) & (tables.col_min <= b_hi))
    rows = np.flatnonzero((tables.row_max >= elev_lo_rad) & (tables.row_min <= elev_hi_rad))
    if cols.size == 0 or rows.size == 0:
        return
    block_at = (slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1))
    b = tables.rel_bearing[block_at]
    db = tables.bearing_step[block_at]
    e = tables.elevation[block_at]
    de = tables.elevation_step[block_at]
    cover = _tent_cdf((b_hi - b) / db) - _tent_cdf((b_lo - b) / db)
    cover *= _tent_cdf((elev_hi_rad - e) / de) - _tent_cdf((elev_lo_rad - e) / de)
    alpha = cover.astype(np.float32)[..., None]
    block = image[block_at]
    block += alpha * (color - block)


# ------------------------------------------------------------------------------ tables


@dataclass(frozen=True, eq=False)
class _Tables:
    """Per-calibration tables: background (H, W, 3) float32, cos/sin of the pixel bearings
    repeated per channel (broadcastable to (H, 3 W)), and a unit-std noise table (flat
    float32, 3 values per pixel)."""

    background: NDArray[np.float32]
    cos_bearing: NDArray[np.float32]
    sin_bearing: NDArray[np.float32]
    noise: NDArray[np.float32]


@dataclass(frozen=True, eq=False)
class _OmniTables(_Tables):
    """Adds the ring pixels sorted by bearing: flat pixel index, bearing (rad), radius (px),
    kernel widths ``(|sin|, |cos|)`` of the screen angle, and the search margin."""

    pixel: NDArray[np.intp]
    bearing: NDArray[np.float64]
    radius: NDArray[np.float64]
    kernel_a: NDArray[np.float64]
    kernel_b: NDArray[np.float64]
    margin_rad: float
    r_min: float
    r_max: float

    def window(self, lo: float, hi: float) -> NDArray[np.intp]:
        """Positions (into the sorted ring arrays) of pixels with bearing in ``[lo, hi]``.

        ``lo``/``hi`` may lie outside [-pi, pi); the window wraps.
        """
        if hi - lo >= TWO_PI:
            return np.arange(self.bearing.size)
        lo_w = wrap_rad(lo)
        hi_w = lo_w + (hi - lo)
        ranges = [(lo_w, min(hi_w, math.pi))]
        if hi_w > math.pi:
            ranges.append((-math.pi, hi_w - TWO_PI))
        parts = [np.arange(*np.searchsorted(self.bearing, [a, z], side="left")) for a, z in ranges]
        return np.concatenate(parts)


@dataclass(frozen=True, eq=False)
class _PinholeTables(_Tables):
    """Adds each pixel's ray: bearing relative to the optical axis (rad, (H, W)), elevation
    (rad), the size of one pixel step in each (rad), the extremes per column and per row (the
    block a landmark can touch), and the field of view."""

    rel_bearing: NDArray[np.float64]
    elevation: NDArray[np.float64]
    bearing_step: NDArray[np.float64]
    elevation_step: NDArray[np.float64]
    col_min: NDArray[np.float64]
    col_max: NDArray[np.float64]
    row_min: NDArray[np.float64]
    row_max: NDArray[np.float64]
    offset_rad: float
    half_view_rad: float
    elevation_lo: float
    elevation_hi: float


def _background_color(
    bearing_rad: NDArray[np.float64], elevation_rad: NDArray[np.float64], backdrop: Backdrop
) -> NDArray[np.float32]:
    """Background colour (..., 3) float32 at the given bearings/elevations (same shape)."""
    wall_lo, wall_hi = _WALL_BAND_RAD
    out = np.empty((*bearing_rad.shape, 3), np.float32)
    out[...] = _ROOM_BGR
    out[elevation_rad < wall_hi] = backdrop.wall_bgr
    out[elevation_rad < wall_lo] = backdrop.floor_bgr
    tex_rng = np.random.default_rng(_TEXTURE_SEED)
    shade = np.ones(bearing_rad.shape)
    for _ in range(4):  # smooth blotches; integer angular frequencies keep the seam continuous
        k = int(tex_rng.integers(1, 7))
        m = tex_rng.uniform(2.0, 9.0)
        ph1, ph2 = tex_rng.uniform(0.0, TWO_PI, 2)
        shade += 0.025 * np.sin(k * bearing_rad + ph1) * np.cos(m * elevation_rad + ph2)
    shade *= 1.0 + 0.012 * tex_rng.standard_normal(bearing_rad.shape)  # fixed grain
    # ceiling light: a little brighter looking up, a little darker at the floor
    shade *= 1.0 + 0.08 * np.clip(elevation_rad / ELEVATION_MAX_RAD, -1.0, 1.0)
    out *= shade[..., None].astype(np.float32)
    return out


def _noise_table(n_px: int) -> NDArray[np.float32]:
    """Unit-std pixel noise for ``1.25 n_px`` pixels: luminance plus a quarter per channel."""
    noise_rng = np.random.default_rng(_TEXTURE_SEED + 1)
    m = n_px + n_px // 4 + 1
    lum = noise_rng.standard_normal((m, 1), dtype=np.float32)
    chroma = noise_rng.standard_normal((m, 3), dtype=np.float32)
    out: NDArray[np.float32] = (lum + np.float32(0.25) * chroma).ravel()
    out /= np.float32(math.sqrt(1.0625))
    return out


def _per_channel(values: NDArray[np.float64]) -> NDArray[np.float32]:
    """(..., W) -> (..., 3 W) float32, each value repeated for B, G, R."""
    out: NDArray[np.float32] = np.repeat(values, 3, axis=-1).astype(np.float32)
    return out


@lru_cache(maxsize=8)
def _tables(calibration: Calibration, backdrop: Backdrop) -> _Tables:
    w, h = calibration.width, calibration.height
    noise = _noise_table(w * h)
    full = ELEVATION_MAX_RAD - ELEVATION_MIN_RAD
    if isinstance(calibration, UnwrappedCalibration):
        col_b = calibration.bearing_of_column(np.arange(w) + 0.5)
        row_e = ELEVATION_MAX_RAD - (np.arange(h) + 0.5) / h * full
        b_grid, e_grid = np.meshgrid(col_b, row_e)
        return _Tables(
            _background_color(b_grid, e_grid, backdrop),
            _per_channel(np.cos(col_b))[None, :],
            _per_channel(np.sin(col_b))[None, :],
            noise,
        )
    if isinstance(calibration, PinholeCalibration):
        return _pinhole_tables(calibration, noise, backdrop)
    assert isinstance(calibration, OmniCalibration)
    return _omni_tables(calibration, noise, backdrop)


def _pinhole_tables(
    cal: PinholeCalibration, noise: NDArray[np.float32], backdrop: Backdrop
) -> _PinholeTables:
    ys, xs = np.mgrid[0 : cal.height, 0 : cal.width].astype(np.float64) + 0.5
    xn, yn = rays_of_pixels(cal, xs, ys)
    rel = -np.arctan(xn)  # bearing relative to the optical axis, CCW positive (left)
    elev = np.arctan2(-yn, np.hypot(xn, 1.0))
    bearing = wrap_rad(rel + cal.offset_rad)
    step_b = np.abs(np.gradient(rel, axis=1)) if cal.width > 1 else np.full_like(rel, 1e-3)
    step_e = np.abs(np.gradient(elev, axis=0)) if cal.height > 1 else np.full_like(elev, 1e-3)
    pad_b, pad_e = 1.5 * float(step_b.max()), 1.5 * float(step_e.max())
    return _PinholeTables(
        background=_background_color(bearing, elev, backdrop),
        cos_bearing=_per_channel(np.cos(bearing)),
        sin_bearing=_per_channel(np.sin(bearing)),
        noise=noise,
        rel_bearing=rel,
        elevation=elev,
        bearing_step=np.maximum(step_b, 1e-9),
        elevation_step=np.maximum(step_e, 1e-9),
        col_min=rel.min(axis=0) - pad_b,
        col_max=rel.max(axis=0) + pad_b,
        row_min=elev.min(axis=1) - pad_e,
        row_max=elev.max(axis=1) + pad_e,
        offset_rad=cal.offset_rad,
        half_view_rad=float(np.abs(rel).max()),
        elevation_lo=float(elev.min()),
        elevation_hi=float(elev.max()),
    )


def _omni_tables(
    cal: OmniCalibration, noise: NDArray[np.float32], backdrop: Backdrop
) -> _OmniTables:
    w, h = cal.width, cal.height
    ys, xs = np.mgrid[0:h, 0:w]
    x, y = xs + 0.5, ys + 0.5  # continuous coordinates of pixel centres
    bearing = cal.bearing_of_pixel(x, y)
    radius = np.hypot(x - cal.cx, y - cal.cy)
    elev = ELEVATION_MIN_RAD + (radius - cal.r_min) / (cal.r_max - cal.r_min) * (
        ELEVATION_MAX_RAD - ELEVATION_MIN_RAD
    )
    background = _background_color(bearing, elev, backdrop)
    background[radius < cal.r_min] = _BODY_BGR
    background[radius >= cal.r_max] = _OUTSIDE_BGR

    r_lo = max(cal.r_min - 1.5, 2.0)
    ring = np.flatnonzero(((radius >= r_lo) & (radius <= cal.r_max + 1.5)).ravel())
    ring_b = bearing.ravel()[ring]
    order = np.argsort(ring_b, kind="stable")
    ring = ring[order]
    screen = np.arctan2(-(y - cal.cy), x - cal.cx).ravel()[ring]
    return _OmniTables(
        background=background,
        cos_bearing=_per_channel(np.cos(bearing)),
        sin_bearing=_per_channel(np.sin(bearing)),
        noise=noise,
        pixel=ring,
        bearing=ring_b[order],
        radius=radius.ravel()[ring],
        kernel_a=np.maximum(np.abs(np.sin(screen)), 0.05),
        kernel_b=np.maximum(np.abs(np.cos(screen)), 0.05),
        margin_rad=math.asin(min(1.0, 1.5 / r_lo)),
        r_min=cal.r_min,
        r_max=cal.r_max,
    )
