"""Per-calibration lookup tables: which angular bin each pixel falls in, and each bin's bearing.

Bearing extraction reduces a class mask to an angular profile (pixel count per bin) and finds
blobs as runs of occupied bins. For an unwrapped panorama the bins are the columns (column
sums); for an omni image they are equal sectors of the ring ``r_min <= r <= r_max`` around the
centre (ring sums through a precomputed pixel -> bin table); for a pinhole camera they are equal
sectors of the whole circle, only those of the field of view holding pixels, each a pixel's
bearing from OpenCV's undistortion. Pixel ``(i, j)`` covers
``[j, j + 1) x [i, i + 1)``; its centre is ``(j + 0.5, i + 0.5)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import TWO_PI, wrap_rad
from data_schemas.calibration import (
    Calibration,
    OmniCalibration,
    PinholeCalibration,
    UnwrappedCalibration,
)
from pipeline.bearings.pinhole import field_of_view_rad, pixel_rays


@dataclass(frozen=True, eq=False)
class UnwrappedLayout:
    """Bins = columns. ``bin_cos``/``bin_sin``: (W,) of each column centre's bearing."""

    calibration: UnwrappedCalibration
    bin_cos: NDArray[np.float64]
    bin_sin: NDArray[np.float64]

    @property
    def n_bins(self) -> int:
        """Number of angular bins (= columns)."""
        return self.calibration.width

    @property
    def bin_width_rad(self) -> float:
        """Angular size of one bin (one column)."""
        return TWO_PI / self.calibration.width

    @property
    def gap_bins(self) -> int:
        """Default gap (empty bins) bridged inside one blob: one column of noise dropout."""
        return 1

    @property
    def fringe_width_rad(self) -> float:
        """Widest mixed-colour fringe: two columns."""
        return 2.0 * self.bin_width_rad


@dataclass(frozen=True, eq=False)
class PixelLayout:
    """Sectors of the circle through a per-pixel table, restricted to a crop of the image.

    Attributes
    ----------
    crop : (slice, slice)
        Rows and columns of the image that can hold bearings.
    ring : ndarray, crop shape, uint8
        255 where a pixel holds a bearing (omni: inside ``r_min <= r <= r_max``), else 0.
    pixel_bin : ndarray, crop shape, int32
        Sector index (0..n_bins-1, in increasing bearing from -pi) of each such pixel, else -1.
    pixel_cos, pixel_sin : ndarray, crop shape, float64
        Cosine and sine of each pixel centre's bearing (pinhole: times the pixel's area in
        bearing x elevation relative to the largest, so that a blob's mean bearing is over
        angle, not pixels).
    n_bins : int
        Number of sectors of the whole circle.
    pixel_row : ndarray, crop shape, int32
        Row of the band-code grid (0 = highest elevation) of each pixel.
    n_rows : int
        Number of rows of the band-code grid.
    """

    crop: tuple[slice, slice]
    ring: NDArray[np.uint8]
    pixel_bin: NDArray[np.int32]
    pixel_cos: NDArray[np.float64]
    pixel_sin: NDArray[np.float64]
    n_bins: int
    pixel_row: NDArray[np.int32]
    n_rows: int

    @property
    def bin_width_rad(self) -> float:
        """Angular size of one sector."""
        return TWO_PI / self.n_bins


@dataclass(frozen=True, eq=False)
class OmniLayout(PixelLayout):
    """Ring sectors of an omni image, restricted to the ring's bounding box (the crop).

    ``n_bins``: one pixel wide at ``r_max`` (at least 90); nearer the centre a pixel spans
    several sectors, so runs bridge gaps of up to ``gap_bins`` empty sectors. Band-grid rows
    are rings one pixel wide, the outermost (``r_max``, the highest elevation) first.
    """

    calibration: OmniCalibration

    @property
    def gap_bins(self) -> int:
        """Default gap (empty sectors) bridged inside one blob: a pixel's span at ``r_min``."""
        cal = self.calibration
        return max(1, math.ceil(cal.r_max / max(cal.r_min, 1.0)))

    @property
    def fringe_width_rad(self) -> float:
        """Widest mixed-colour fringe: two pixels at the ring's mid radius."""
        cal = self.calibration
        return 2.0 / max(0.5 * (cal.r_min + cal.r_max), 1.0)


@dataclass(frozen=True, eq=False)
class PinholeLayout(PixelLayout):
    """Sectors of a pinhole image: the whole image, band-grid rows = image rows.

    ``n_bins``: a sector is as wide as the largest bearing step between two horizontally
    adjacent pixels anywhere in the image, so that no sector inside the field of view is
    skipped along a row; only the field of view's sectors hold pixels, so blobs never wrap
    from one edge of the image to the other.
    """

    calibration: PinholeCalibration
    field_of_view_rad: tuple[float, float]
    #: bearings (rad) seen in every row: where distortion bends the image's left and right
    #: edges, the view is narrower in some rows than in others
    inner_view_rad: tuple[float, float]

    def cut_by_edge(self, bearing_rad: float, width_rad: float) -> bool:
        """True if a blob at ``bearing_rad``, ``width_rad`` wide, reaches within a sector of
        the image's left or right edge: part of it may lie outside, and its bearing with it."""
        lo, hi = self.inner_view_rad
        reach = 0.5 * width_rad + self.bin_width_rad
        centre = 0.5 * (lo + hi)
        off = float(wrap_rad(bearing_rad - centre))
        return off + reach >= hi - centre or off - reach <= lo - centre

    @property
    def gap_bins(self) -> int:
        """Default gap (empty sectors) bridged inside one blob: one column of noise dropout."""
        return 1

    @property
    def fringe_width_rad(self) -> float:
        """Widest mixed-colour fringe: two sectors."""
        return 2.0 * self.bin_width_rad


Layout = UnwrappedLayout | OmniLayout | PinholeLayout


def make_layout(calibration: Calibration) -> Layout:
    """Precompute the lookup tables of ``calibration`` (done once per extractor)."""
    if isinstance(calibration, UnwrappedCalibration):
        bearing = calibration.bearing_of_column(np.arange(calibration.width) + 0.5)
        return UnwrappedLayout(calibration, np.cos(bearing), np.sin(bearing))
    if isinstance(calibration, PinholeCalibration):
        return _pinhole_layout(calibration)
    cal = calibration
    x0 = max(0, math.floor(cal.cx - cal.r_max))
    x1 = min(cal.width, math.ceil(cal.cx + cal.r_max) + 1)
    y0 = max(0, math.floor(cal.cy - cal.r_max))
    y1 = min(cal.height, math.ceil(cal.cy + cal.r_max) + 1)
    x0, y0 = min(x0, x1), min(y0, y1)
    yc, xc = np.mgrid[y0:y1, x0:x1].astype(np.float64) + 0.5
    radius = np.hypot(xc - cal.cx, yc - cal.cy)
    inside = (radius >= cal.r_min) & (radius <= cal.r_max)
    bearing = cal.bearing_of_pixel(xc, yc)
    n_bins = max(90, math.ceil(TWO_PI * cal.r_max))
    sector = np.floor((bearing + math.pi) * (n_bins / TWO_PI)).astype(np.int32) % n_bins
    n_rows = max(1, math.ceil(cal.r_max - cal.r_min) + 1)
    return OmniLayout(
        calibration=cal,
        crop=(slice(y0, y1), slice(x0, x1)),
        ring=np.where(inside, 255, 0).astype(np.uint8),
        pixel_bin=np.where(inside, sector, -1).astype(np.int32),
        pixel_cos=np.cos(bearing),
        pixel_sin=np.sin(bearing),
        n_bins=n_bins,
        pixel_row=np.clip(np.floor(cal.r_max - radius), 0, n_rows - 1).astype(np.int32),
        n_rows=n_rows,
    )


def _pinhole_layout(cal: PinholeCalibration) -> PinholeLayout:
    yc, xc = np.mgrid[0 : cal.height, 0 : cal.width].astype(np.float64) + 0.5
    bearing, elevation = pixel_rays(cal, xc, yc)
    if cal.width > 1 and cal.height > 1:
        db_dy, db_dx = (wrap_rad(g) for g in np.gradient(bearing))
        de_dy, de_dx = np.gradient(elevation)
        width_rad = np.abs(db_dx)
        solid = np.abs(db_dx * de_dy - db_dy * de_dx)  # the pixel's area in (bearing, elevation)
    else:
        width_rad = solid = np.full(bearing.shape, TWO_PI / 360.0)
    step = max(float(width_rad.max()), 1e-6)
    n_bins = max(90, math.floor(TWO_PI / step))
    # pixels are denser in bearing and elevation towards the edges (and wherever distortion
    # squeezes them): weighting each by its area in (bearing, elevation) makes the mean bearing
    # of a landmark (a box in those coordinates) its angular centre
    weight = solid / max(float(solid.max()), 1e-12)
    sector = np.floor((bearing + math.pi) * (n_bins / TWO_PI)).astype(np.int32) % n_bins
    return PinholeLayout(
        crop=(slice(None), slice(None)),
        ring=np.full(bearing.shape, 255, np.uint8),
        pixel_bin=sector,
        pixel_cos=np.cos(bearing) * weight,
        pixel_sin=np.sin(bearing) * weight,
        n_bins=n_bins,
        pixel_row=np.broadcast_to(np.arange(cal.height, dtype=np.int32)[:, None], bearing.shape),
        n_rows=cal.height,
        calibration=cal,
        field_of_view_rad=field_of_view_rad(cal),
        inner_view_rad=(float(bearing[:, -1].max()), float(bearing[:, 0].min())),
    )
