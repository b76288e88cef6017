"""Colour classes: OpenCV HSV boxes (H 0..179, S and V 0..255) for the catalog's colour names.

A box is ``lo <= (h, s, v) <= hi`` per channel, except hue, which wraps when ``lo_h > hi_h``
(red: ``h >= 168 or h <= 12``). Defaults are +-12 hue units (+-24 deg) around each nominal
colour of :data:`data_schemas.colors.NOMINAL_BGR`, saturation >= 90 and value >= 50, so dim
lighting (value down to ~25% of nominal) and sensor noise still pass while grey and white do
not. A landmark's ``hsv_lo``/``hsv_hi`` in the session metadata replace the default box; a
coded landmark's ``band_hsv`` (one box per band) replace its bands' default boxes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from data_schemas.colors import COLOR_NAMES, band_problem
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

    @property
    def hue_centre(self) -> float:
        """The middle of the hue range (OpenCV units, 0..180)."""
        h_lo, h_hi = self.lo[0], self.hi[0]
        span = (h_hi - h_lo) % 180 if self.wraps else h_hi - h_lo
        return (h_lo + span / 2) % 180

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
    if spec.bands:
        raise LandmarkCatalogError(
            f"landmark {spec.name!r} is coded (bands {list(spec.bands)}); its bands' boxes are "
            "band_boxes_for's"
        )
    color = _check_color(spec.name, spec.color)
    if spec.band_hsv:
        raise LandmarkCatalogError(
            f"landmark {spec.name!r} has one colour: give 'hsv' one box {{lo, hi}}, not a list"
        )
    if spec.hsv_lo is None and spec.hsv_hi is None:
        return DEFAULT_HSV[color]
    if spec.hsv_lo is None or spec.hsv_hi is None:
        raise LandmarkCatalogError(
            f"landmark {spec.name!r}: an HSV override needs both 'lo' and 'hi'"
        )
    return _box(spec.name, spec.hsv_lo, spec.hsv_hi)


def band_boxes_for(spec: LandmarkSpec) -> tuple[HsvBox, ...]:
    """The HSV box of each band of coded landmark ``spec`` (top to bottom): its per-band
    override if given, else each colour's default.

    Raises
    ------
    LandmarkCatalogError
        Unknown colour name, a single box given for a code, a count of boxes other than the
        number of bands, or a malformed box.
    """
    for color in spec.bands:
        _check_color(spec.name, color)
    if spec.hsv_lo is not None or spec.hsv_hi is not None:
        raise LandmarkCatalogError(
            f"landmark {spec.name!r} is coded: give 'hsv' as a list of {len(spec.bands)} boxes "
            "{lo, hi}, one per band, top to bottom"
        )
    if not spec.band_hsv:
        return tuple(DEFAULT_HSV[c] for c in spec.bands)
    if len(spec.band_hsv) != len(spec.bands):
        raise LandmarkCatalogError(
            f"landmark {spec.name!r} has {len(spec.bands)} bands but {len(spec.band_hsv)} HSV "
            "boxes; give one box per band, top to bottom"
        )
    return tuple(_box(spec.name, lo, hi) for lo, hi in spec.band_hsv)


def _box(name: str, lo: Sequence[int], hi: Sequence[int]) -> HsvBox:
    """An override box of landmark ``name``, checked."""
    if len(lo) != 3 or len(hi) != 3:
        raise LandmarkCatalogError(
            f"landmark {name!r}: HSV override bounds need 3 values (h, s, v) each"
        )
    try:
        return HsvBox((int(lo[0]), int(lo[1]), int(lo[2])), (int(hi[0]), int(hi[1]), int(hi[2])))
    except LandmarkCatalogError as exc:
        raise LandmarkCatalogError(f"landmark {name!r}: {exc}") from None


def _check_color(name: str, color: str | None) -> str:
    """``color`` if it is a known colour name, else raise LandmarkCatalogError."""
    if color is None or color not in DEFAULT_HSV:
        raise LandmarkCatalogError(
            f"landmark {name!r} has unknown colour {color!r}; "
            f"known colours: {', '.join(DEFAULT_HSV)}"
        )
    return color


@dataclass(frozen=True)
class LandmarkClass:
    """What a detection can tell apart: one colour, or one band code.

    Attributes
    ----------
    label : str
        ``"red"`` or ``"magenta-yellow"`` (``data_schemas.colors.class_label``).
    colors : tuple of str
        The colour (one) or the bands (two or more, top to bottom).
    boxes : tuple of HsvBox
        The HSV box of each colour (the landmark's override if given, else the defaults).
    landmarks : tuple of str
        Catalog names of this class, in catalog order; more than one makes the class ambiguous.
    """

    label: str
    colors: tuple[str, ...]
    boxes: tuple[HsvBox, ...]
    landmarks: tuple[str, ...]

    @property
    def coded(self) -> bool:
        """True for a band code (two or more colours)."""
        return len(self.colors) > 1


def landmark_classes(catalog: Sequence[LandmarkSpec]) -> list[LandmarkClass]:
    """Group a catalog into classes (landmarks that look alike), in order of first appearance.

    Raises
    ------
    LandmarkCatalogError
        Unknown colour, malformed HSV override, a code with fewer than two bands or two equal
        adjacent bands, or two landmarks of one class with different HSV boxes.
    """
    classes: dict[str, LandmarkClass] = {}
    for spec in catalog:
        if spec.bands:
            problem = band_problem(spec.bands)
            if problem:
                raise LandmarkCatalogError(f"landmark {spec.name!r}: {problem}")
            colors = tuple(spec.bands)
            boxes = band_boxes_for(spec)
        else:
            boxes = (hsv_box_for(spec),)
            colors = (str(spec.color),)
        same = classes.get(spec.label)
        if same is None:
            classes[spec.label] = LandmarkClass(spec.label, colors, boxes, (spec.name,))
        elif same.boxes != boxes:
            raise LandmarkCatalogError(
                f"landmarks {same.landmarks[0]!r} and {spec.name!r} are both {spec.label} but "
                "have different HSV boxes; give landmarks of one class the same override"
            )
        else:
            classes[spec.label] = LandmarkClass(
                same.label, same.colors, same.boxes, (*same.landmarks, spec.name)
            )
    return list(classes.values())
