"""Camera calibration: how an image position maps to a bearing.

Three models (each stored in the session metadata under ``camera.calibration``):

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
* ``pinhole`` (an ordinary camera, OpenCV's model): intrinsics ``fx, fy, cx, cy`` (the ``K``
  matrix of OpenCV and ROS, pixel centres at integer coordinates) and distortion coefficients
  ``D`` of one of ROS's ``distortion_model`` names: ``plumb_bob`` (k1, k2, p1, p2[, k3]),
  ``rational_polynomial`` (k1, k2, p1, p2, k3, k4, k5, k6) or ``equidistant`` (OpenCV's fisheye
  model, k1..k4). The camera is level (its optical axis horizontal, image rows horizontal); a
  pixel is undistorted to the normalized image point ``(xn, yn)`` (x right, y down) and::

      bearing = wrap(offset - atan(xn))

  ``offset`` (default 0) is the bearing of the optical axis: the camera's mounted yaw, counter-
  clockwise from the robot's forward direction. The undistortion itself (OpenCV) lives with
  bearing extraction (``pipeline/bearings/pinhole.py``).

Bearings are radians relative to the robot heading, counter-clockwise positive, in [-pi, pi).
JSON uses degrees with ``_deg`` suffixes.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
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


#: ROS ``distortion_model`` names -> the numbers of coefficients accepted.
DISTORTION_SIZES: dict[str, tuple[int, ...]] = {
    "plumb_bob": (0, 4, 5),
    "rational_polynomial": (0, 8),
    "equidistant": (0, 4),
}

DistortionModel = Literal["plumb_bob", "rational_polynomial", "equidistant"]


@dataclass(frozen=True)
class PinholeCalibration:
    """A level pinhole camera with OpenCV distortion (see the module docstring).

    Attributes
    ----------
    width, height : int
        Image size in pixels.
    fx, fy, cx, cy : float
        Focal lengths and principal point, pixels (OpenCV/ROS ``K``: the centre of pixel
        ``(row i, column j)`` is at ``(j, i)``).
    distortion : tuple of float
        Distortion coefficients ``D`` in OpenCV's order for ``distortion_model`` (empty: none).
    distortion_model : {"plumb_bob", "rational_polynomial", "equidistant"}
        ROS's name of the distortion model (``equidistant`` is OpenCV's fisheye model).
    offset_rad : float
        Bearing of the optical axis (mounted yaw), rad, counter-clockwise from forward.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, ...] = ()
    distortion_model: DistortionModel = "plumb_bob"
    offset_rad: float = 0.0
    model: Literal["pinhole"] = "pinhole"

    def __post_init__(self) -> None:
        _check_size(self.width, self.height)
        values = (self.fx, self.fy, self.cx, self.cy, self.offset_rad, *self.distortion)
        if not all(math.isfinite(v) for v in values):
            raise CalibrationError("pinhole calibration has a NaN or infinite value")
        if self.fx <= 0 or self.fy <= 0:
            raise CalibrationError(
                f"pinhole calibration needs positive focal lengths, got fx={self.fx:g}, "
                f"fy={self.fy:g} (pixels)"
            )
        sizes = DISTORTION_SIZES.get(self.distortion_model)
        if sizes is None:
            raise CalibrationError(
                f"unknown distortion model {self.distortion_model!r}; expected one of "
                f"{', '.join(DISTORTION_SIZES)}"
            )
        if len(self.distortion) not in sizes:
            raise CalibrationError(
                f"distortion model {self.distortion_model!r} takes "
                f"{' or '.join(str(n) for n in sizes if n)} coefficients, got "
                f"{len(self.distortion)}"
            )

    @property
    def camera_matrix(self) -> NDArray[np.float64]:
        """The (3, 3) intrinsic matrix ``K``."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def bearing_of_normalized(self, xn: NDArray[np.floating] | float) -> NDArray[np.float64]:
        """Bearing (rad, [-pi, pi)) of undistorted normalized image x coordinates (any shape)."""
        return wrap_rad(self.offset_rad - np.arctan(np.asarray(xn, np.float64)))

    def to_dict(self) -> dict[str, Any]:
        """JSON form (degrees with ``_deg`` suffix)."""
        return {
            "model": "pinhole",
            "width": self.width,
            "height": self.height,
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
            "distortion_model": self.distortion_model,
            "distortion": list(self.distortion),
            "offset_deg": math.degrees(self.offset_rad),
        }


Calibration = UnwrappedCalibration | OmniCalibration | PinholeCalibration


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
        if model == "pinhole":
            return PinholeCalibration(
                width,
                height,
                fx=float(d["fx"]),
                fy=float(d["fy"]),
                cx=float(d["cx"]),
                cy=float(d["cy"]),
                distortion=tuple(float(v) for v in d.get("distortion", ())),
                distortion_model=d.get("distortion_model", "plumb_bob"),
                offset_rad=math.radians(float(d.get("offset_deg", 0.0))),
            )
    except KeyError as exc:
        raise CalibrationError(f"camera calibration is missing key {exc.args[0]!r}") from None
    except (TypeError, ValueError) as exc:
        raise CalibrationError(f"camera calibration has a malformed value: {exc}") from None
    raise CalibrationError(
        f"unknown camera model {model!r}; expected 'unwrapped', 'omni' or 'pinhole'"
    )


def pinhole_from_camera_info(
    doc: Mapping[str, Any], *, offset_rad: float = 0.0
) -> PinholeCalibration:
    """A pinhole calibration from a ROS ``camera_info`` or an OpenCV calibration, as a mapping.

    Accepted forms (keys as their tools write them):

    * ROS 2 ``sensor_msgs/CameraInfo`` (``width``, ``height``, ``k``, ``d``,
      ``distortion_model``), or ROS 1's (``K``, ``D``);
    * the YAML of ROS's ``camera_calibration`` (``image_width``, ``image_height``,
      ``camera_matrix: {data}``, ``distortion_coefficients: {data}``, ``distortion_model``);
    * OpenCV's ``FileStorage`` (``camera_matrix`` and ``distortion_coefficients`` as matrices,
      i.e. nested lists or ``{rows, cols, data}``; ``image_width``, ``image_height``; the
      model is ``plumb_bob`` or ``rational_polynomial`` by the number of coefficients unless
      ``distortion_model`` says ``equidistant`` / ``fisheye``).

    An ``offset_deg`` key (the camera's mounted yaw) overrides ``offset_rad``.

    Raises
    ------
    CalibrationError
        A missing or malformed key, a matrix that is not 3 x 3, an unknown model.
    """
    try:
        width = int(_first(doc, "width", "image_width"))
        height = int(_first(doc, "height", "image_height"))
        k = _flat(_first(doc, "k", "K", "camera_matrix"))
        d = _flat(_first(doc, "d", "D", "distortion_coefficients", default=[]))
        model = str(doc.get("distortion_model", "")).lower()
        if "offset_deg" in doc:
            offset_rad = math.radians(float(doc["offset_deg"]))
    except KeyError as exc:
        raise CalibrationError(f"camera info is missing key {exc.args[0]}") from None
    except (TypeError, ValueError) as exc:
        raise CalibrationError(f"camera info has a malformed value: {exc}") from None
    if len(k) != 9:
        raise CalibrationError(f"camera matrix K must have 9 values (3 x 3), got {len(k)}")
    if model == "fisheye":
        model = "equidistant"
    if not model:
        model = "rational_polynomial" if len(d) == 8 else "plumb_bob"
    if model == "plumb_bob" and len(d) > 5 and not any(d[5:]):
        d = d[:5]  # ROS pads plumb_bob to 5; some tools write 8 or 14 with zeros past k3
    if model not in DISTORTION_SIZES:
        raise CalibrationError(
            f"unknown distortion model {model!r}; expected one of {', '.join(DISTORTION_SIZES)}"
        )
    if abs(k[1]) > 1e-9 * abs(k[0]) or k[3] or k[6] or k[7] or k[8] != 1.0:
        raise CalibrationError(
            f"camera matrix K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (no skew), got {k}"
        )
    return PinholeCalibration(
        width,
        height,
        fx=k[0],
        fy=k[4],
        cx=k[2],
        cy=k[5],
        distortion=tuple(d),
        distortion_model=model,  # type: ignore[arg-type]  # checked above
        offset_rad=offset_rad,
    )


def _first(doc: Mapping[str, Any], *keys: str, default: Any = None) -> Any:
    """The value of the first of ``keys`` in ``doc`` (KeyError naming them all if none)."""
    for key in keys:
        if key in doc:
            return doc[key]
    if default is not None:
        return default
    raise KeyError(" or ".join(repr(k) for k in keys))


def _flat(value: Any) -> list[float]:
    """A matrix as a flat list of floats: nested lists, or a ``{rows, cols, data}`` mapping."""
    if isinstance(value, Mapping):
        value = value["data"]
    out = [float(v) for v in np.asarray(value, np.float64).ravel()]
    if not all(math.isfinite(v) for v in out):
        raise ValueError("NaN or infinite value")
    return out


def default_omni(width: int, height: int) -> OmniCalibration:
    """An omni calibration centred in the image, ring from 25% to 95% of the half-size."""
    half = min(width, height) / 2
    return OmniCalibration(
        width, height, cx=width / 2, cy=height / 2, r_min=0.25 * half, r_max=0.95 * half
    )


def _check_size(width: int, height: int) -> None:
    if width <= 0 or height <= 0:
        raise CalibrationError(f"image size must be positive, got {width}x{height}")
