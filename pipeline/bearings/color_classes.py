"""Colour classes: OpenCV HSV boxes (H 0..179, S and V 0..255) for the catalog's colour names.

A box is ``lo <= (h, s, v) <= hi`` per channel, except hue, which wraps when ``lo_h > hi_h``
(red: ``h >= 168 or h <= 12``). Defaults are +-12 hue units (+-24 deg) around each nominal
colour of :data:`data_schemas.colors.NOMINAL_BGR`, saturation >= 90 and value >= 50, so dim
lighting (value down to ~25% of nominal) and sensor noise still pass while grey and white do
not. A landmark's ``hsv_lo``/``hsv_hi`` in the session metadata replace the default box.
"""

from __future__ import annotations

from dataclasses import dataclass

from data_schemas.colors import COLOR_NAMES
from data_schemas.errors import CalibrationError
from data_schemas.session import LandmarkSpec


class LandmarkCatalogError(CalibrationError):
    """The landmark catalog cannot be turned into colour classes (unknown colour, bad HSV box)."""


@dataclass(frozen=True)
class HsvBox:
    """An OpenCV HSV box; hue wraps through 179 -> 0 when ``lo[0] > hi[0]``."""

    lo: tuple[int, int, int]
    hi: tuple[int, int, int]

    def __post_init__(self) -> None:
        limits = (179, 255, 255)
        for channel, (a, b, top) in enumerate(zip(self.lo, self.hi, limits, strict=True)):
            if not (0 <= a <= top and 0 <= b <= top):
                raise LandmarkCatalogError(
                    f"HSV box {self.lo}..{self.hi}: channel {'HSV'[channel]} must lie in 0..{top}"
                )
            if channel > 0 and a > b:
                raise LandmarkCatalogError(
                    f"HSV box {self.lo}..{self.hi}: {'HSV'[channel]} lower bound exceeds upper"
                )

    @property
    def wraps(self) -> bool:
        """True if the hue range runs through 179 -> 0 (red)."""
        return self.lo[0] > self.hi[0]

    def hue_values(self) -> list[int]:
        """The hue values (0..179) inside the box."""
        h_lo, h_hi = self.lo[0], self.hi[0]
        if self.wraps:
            return [*range(h_lo, 180), *range(h_hi + 1)]
        return list(range(h_lo, h_hi + 1))


_S_LO, _V_LO, _HUE_HALF_WIDTH = 90, 50, 12
_NOMINAL_HUE = {"red": 0, "yellow": 30, "green": 60, "cyan": 90, "blue": 120, "magenta": 150}


def _default_box(hue: int) -> HsvBox:
    return HsvBox(
        ((hue - _HUE_HALF_WIDTH) % 180, _S_LO, _V_LO),
        ((hue + _HUE_HALF_WIDTH) % 180, 255, 255),
    )


#: colour name -> default HSV box (every name of ``data_schemas.colors.COLOR_NAMES``).
DEFAULT_HSV: dict[str, HsvBox] = {name: _default_box(_NOMINAL_HUE[name]) for name in COLOR_NAMES}


def hsv_box_for(spec: LandmarkSpec) -> HsvBox:
    """The HSV box that detects landmark ``spec``: its override if given, else its colour's.

    Raises
    ------
    LandmarkCatalogError
        Unknown colour name, only one of ``hsv_lo``/``hsv_hi`` given, or a malformed box.
    """
    if spec.color not in DEFAULT_HSV:
        raise LandmarkCatalogError(
            f"landmark {spec.name!r} has unknown colour {spec.color!r}; "
            f"known colours: {', '.join(DEFAULT_HSV)}"
        )
    if spec.hsv_lo is None and spec.hsv_hi is None:
        return DEFAULT_HSV[spec.color]
    if spec.hsv_lo is None or spec.hsv_hi is None:
        raise LandmarkCatalogError(
            f"landmark {spec.name!r}: an HSV override needs both 'lo' and 'hi'"
        )
    if len(spec.hsv_lo) != 3 or len(spec.hsv_hi) != 3:
        raise LandmarkCatalogError(
            f"landmark {spec.name!r}: HSV override bounds need 3 values (h, s, v) each"
        )
    try:
        return HsvBox(
            (int(spec.hsv_lo[0]), int(spec.hsv_lo[1]), int(spec.hsv_lo[2])),
            (int(spec.hsv_hi[0]), int(spec.hsv_hi[1]), int(spec.hsv_hi[2])),
        )
    except LandmarkCatalogError as exc:
        raise LandmarkCatalogError(f"landmark {spec.name!r}: {exc}") from None
