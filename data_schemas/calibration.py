"""Panoramic camera calibration: how an image position maps to a bearing.

Two models (both stored in the session metadata under ``camera.calibration``):

* ``unwrapped`` (cylindrical panorama): the bearing is linear in the column. With ``u`` the
  continuous column coordinate (pixel ``j`` covers ``[j, j + 1)``, centre ``j + 0.5``)::

      bearing = wrap(offset + direction * 2 pi u / width)

  Defaults: ``offset = pi`` and ``direction = -1``: column 0 looks backwards, the image centre
  looks forward, and bearings decrease to the right, as a person sees a panorama.
* ``omni`` (raw catadioptric "donut" image): the bearing is the polar angle around the image
  centre ``(cx, cy)``, measured on screen counter-clockwise from the +x (right) axis, taken only
  between radii ``r_min`` and ``r_max`` (pixels)::

      theta = atan2(-(y - cy), x - cx)
      bearing = wrap(offset + direction * theta)

  Defaults: ``offset = -pi/2``, ``direction = +1``: forward is up in the image, left is left.

Bearings are radians relative to the robot heading, counter-clockwise positive, in [-pi, pi).
JSON uses degrees with ``_deg`` suffixes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import TWO_PI, wrap_rad
from data_schemas.errors import CalibrationError


@dataclass(frozen=True)
class UnwrappedCalibration:
    """Cylindrical panorama: bearing linear in the column.

    Attributes
    ----------
    width, height : int
        Image size in pixels.
    offset_rad : float
        Bearing at the left edge of column 0 (u = 0).
    direction : {-1, +1}
        +1 if bearings increase with the column, -1 if they decrease.
    """

    width: int
    height: int
    offset_rad: float = math.pi
    direction: int = -1
    model: Literal["unwrapped"] = "unwrapped"

    def __post_init__(self) -> None:
        _check_size(self.width, self.height)
        if self.direction not in (-1, 1):
            raise CalibrationError(f"calibration direction must be +1 or -1, got {self.direction}")

    def bearing_of_column(self, u: NDArray[np.floating] | float) -> NDArray[np.float64]:
        """Bearing (rad, [-pi, pi)) of continuous column coordinates ``u`` (any shape)."""
        u_arr = np.asarray(u, dtype=np.float64)
        return wrap_rad(self.offset_rad + self.direction * (TWO_PI / self.width) * u_arr)

    def column_of_bearing(self, bearing_rad: NDArray[np.floating] | float) -> NDArray[np.float64]:
        """Continuous column coordinate in [0, width) that looks along ``bearing_rad``."""
        b = np.asarray(bearing_rad, dtype=np.float64)
        frac = self.direction * (b - self.offset_rad) / TWO_PI
        frac = frac - np.floor(frac)
        frac = np.where(frac >= 1.0, 0.0, frac)  # -tiny - floor(-tiny) rounds to 1.0
        return frac * self.width

    def to_dict(self) -> dict[str, Any]:
        """JSON form (degrees with ``_deg`` suffix)."""
        return {
            "model": "unwrapped",
            "width": self.width,
            "height": self.height,
            "offset_deg": math.degrees(self.offset_rad),
            "direction": self.direction,
        }


@dataclass(frozen=True)
class OmniCalibration:
    """Catadioptric donut image: bearing = polar angle around ``(cx, cy)`` between two radii.

    Attributes
    ----------
    width, height : int
        Image size in pixels.
    cx, cy : float
        Image centre of the mirror, pixels (x right, y down).
    r_min, r_max : float
        Radii (pixels) of the ring that holds the panorama.
    offset_rad : float
        Bearing of the on-screen +x axis (theta = 0).
    direction : {-1, +1}
        +1 if bearings increase counter-clockwise on screen.
    """

    width: int
    height: int
    cx: float
    cy: float
    r_min: float
    r_max: float
    offset_rad: float = -math.pi / 2
    direction: int = 1
    model: Literal["omni"] = "omni"

    def __post_init__(self) -> None:
        _check_size(self.width, self.height)
        if self.direction not in (-1, 1):
            raise CalibrationError(f"calibration direction must be +1 or -1, got {self.direction}")
        if not 0 <= self.r_min < self.r_max:
            raise CalibrationError(
                f"omni calibration needs 0 <= r_min < r_max, got r_min={self.r_min}, "
                f"r_max={self.r_max}"
            )
        if not (0 <= self.cx <= self.width and 0 <= self.cy <= self.height):
            raise CalibrationError(
                f"omni calibration centre ({self.cx:g}, {self.cy:g}) is outside the "
                f"{self.width}x{self.height} image; give cx, cy of the mirror in pixels"
            )
        corner_px = math.hypot(
            max(self.cx, self.width - self.cx), max(self.cy, self.height - self.cy)
        )
        if self.r_min >= corner_px:
            raise CalibrationError(
                f"omni calibration ring r_min={self.r_min:g} px lies outside the "
                f"{self.width}x{self.height} image; give r_min and r_max in pixels"
            )

    def bearing_of_pixel(
        self, x: NDArray[np.floating] | float, y: NDArray[np.floating] | float
    ) -> NDArray[np.float64]:
        """Bearing (rad, [-pi, pi)) of continuous pixel coordinates ``(x, y)`` (any shape)."""
        dx = np.asarray(x, np.float64) - self.cx
        dy = np.asarray(y, np.float64) - self.cy
        theta = np.arctan2(-dy, dx)
        return wrap_rad(self.offset_rad + self.direction * theta)

    def pixel_of_bearing(
        self, bearing_rad: NDArray[np.floating] | float, radius: NDArray[np.floating] | float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Continuous pixel coordinates ``(x, y)`` at ``radius`` pixels along ``bearing_rad``."""
        theta = self.direction * (np.asarray(bearing_rad, np.float64) - self.offset_rad)
        r = np.asarray(radius, np.float64)
        return self.cx + r * np.cos(theta), self.cy - r * np.sin(theta)

    def to_dict(self) -> dict[str, Any]:
        """JSON form (degrees with ``_deg`` suffix)."""
        return {
            "model": "omni",
            "width": self.width,
            "height": self.height,
            "cx": self.cx,
            "cy": self.cy,
            "r_min": self.r_min,
            "r_max": self.r_max,
            "offset_deg": math.degrees(self.offset_rad),
            "direction": self.direction,
        }


Calibration = UnwrappedCalibration | OmniCalibration


def calibration_from_dict(d: dict[str, Any]) -> Calibration:
    """Build a calibration from its JSON form (see module docstring); raise CalibrationError."""
    try:
        model = d["model"]
        width, height = int(d["width"]), int(d["height"])
        if model == "unwrapped":
            return UnwrappedCalibration(
                width,
                height,
                offset_rad=math.radians(float(d.get("offset_deg", 180.0))),
                direction=int(d.get("direction", -1)),
            )
        if model == "omni":
            return OmniCalibration(
                width,
                height,
                cx=float(d.get("cx", width / 2)),
                cy=float(d.get("cy", height / 2)),
                r_min=float(d["r_min"]),
                r_max=float(d["r_max"]),
                offset_rad=math.radians(float(d.get("offset_deg", -90.0))),
                direction=int(d.get("direction", 1)),
            )
    except KeyError as exc:
        raise CalibrationError(f"camera calibration is missing key {exc.args[0]!r}") from None
    except (TypeError, ValueError) as exc:
        raise CalibrationError(f"camera calibration has a malformed value: {exc}") from None
    raise CalibrationError(f"unknown camera model {model!r}; expected 'unwrapped' or 'omni'")


def default_omni(width: int, height: int) -> OmniCalibration:
    """An omni calibration centred in the image, ring from 25% to 95% of the half-size."""
    half = min(width, height) / 2
    return OmniCalibration(
        width, height, cx=width / 2, cy=height / 2, r_min=0.25 * half, r_max=0.95 * half
    )


def _check_size(width: int, height: int) -> None:
    if width <= 0 or height <= 0:
        raise CalibrationError(f"image size must be positive, got {width}x{height}")
