"""Per-calibration lookup tables: which angular bin each pixel falls in, and each bin's bearing.

Bearing extraction reduces a class mask to an angular profile (pixel count per bin) and finds
blobs as runs of occupied bins. For an unwrapped panorama the bins are the columns (column
sums); for an omni image they are equal sectors of the ring ``r_min <= r <= r_max`` around the
centre (ring sums through a precomputed pixel -> bin table). Pixel ``(i, j)`` covers
``[j, j + 1) x [i, i + 1)``; its centre is ``(j + 0.5, i + 0.5)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import TWO_PI
from data_schemas.calibration import Calibration, OmniCalibration, UnwrappedCalibration


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
class OmniLayout:
    """Ring sectors of an omni image, restricted to the ring's bounding box (the crop).

    Attributes
    ----------
    crop : (slice, slice)
        Rows and columns of the image that hold the ring.
    ring : ndarray, crop shape, uint8
        255 inside ``r_min <= r <= r_max``, else 0.
    pixel_bin : ndarray, crop shape, int32
        Sector index (0..n_bins-1, in increasing bearing from -pi) of each ring pixel, else -1.
    pixel_cos, pixel_sin : ndarray, crop shape, float64
        Cosine and sine of each pixel centre's bearing.
    n_bins : int
        Number of sectors: one pixel wide at ``r_max`` (at least 90). Nearer the centre a pixel
        spans several sectors, so runs bridge gaps of up to ``gap_bins`` empty sectors.
    """

    calibration: OmniCalibration
    crop: tuple[slice, slice]
    ring: NDArray[np.uint8]
    pixel_bin: NDArray[np.int32]
    pixel_cos: NDArray[np.float64]
    pixel_sin: NDArray[np.float64]
    n_bins: int

    @property
    def bin_width_rad(self) -> float:
        """Angular size of one sector."""
        return TWO_PI / self.n_bins

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


Layout = UnwrappedLayout | OmniLayout


def make_layout(calibration: Calibration) -> Layout:
    """Precompute the lookup tables of ``calibration`` (done once per extractor)."""
    if isinstance(calibration, UnwrappedCalibration):
        bearing = calibration.bearing_of_column(np.arange(calibration.width) + 0.5)
        return UnwrappedLayout(calibration, np.cos(bearing), np.sin(bearing))
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
    return OmniLayout(
        calibration=cal,
        crop=(slice(y0, y1), slice(x0, x1)),
        ring=np.where(inside, 255, 0).astype(np.uint8),
        pixel_bin=np.where(inside, sector, -1).astype(np.int32),
        pixel_cos=np.cos(bearing),
        pixel_sin=np.sin(bearing),
        n_bins=n_bins,
    )
