"""Per-pixel colour classification: BGR image -> one bit per colour class.

One ``cvtColor`` to HSV, one ``inRange`` per distinct saturation/value window, and one 256-entry
hue lookup table per group of up to 8 classes give a uint8 image whose bit ``k`` is set where
the pixel lies in class ``k``'s box. This costs about the same as two ``inRange`` calls whatever
the number of classes (a separate 3-channel ``inRange`` per class would cost one each, two for
red), and hue wrap-around is free in the table.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from pipeline.bearings.color_classes import HsvBox


@dataclass(frozen=True)
class ClassBit:
    """Where class ``k`` lives in the classifier output: plane ``plane``, bit value ``bit``."""

    plane: int
    bit: int


class ColorClassifier:
    """Classify BGR pixels into HSV boxes, up to 8 classes per output plane.

    Parameters
    ----------
    boxes : sequence of HsvBox
        One per class, in order; class ``k`` is reported at ``self.slots[k]``.
    """

    def __init__(self, boxes: Sequence[HsvBox]) -> None:
        self.slots = [ClassBit(k // 8, 1 << (k % 8)) for k in range(len(boxes))]
        self.n_planes = (len(boxes) + 7) // 8
        # S/V window -> lookup table per plane (hue -> bits of the classes with that window)
        self._groups: dict[tuple[int, int, int, int], NDArray[np.uint8]] = {}
        for box, slot in zip(boxes, self.slots, strict=True):
            window = (box.lo[1], box.lo[2], box.hi[1], box.hi[2])
            luts = self._groups.setdefault(window, np.zeros((self.n_planes, 256), np.uint8))
            luts[slot.plane, box.hue_values()] |= np.uint8(slot.bit)

    def classify(
        self, image_bgr: NDArray[np.uint8], valid: NDArray[np.uint8] | None = None
    ) -> list[NDArray[np.uint8]]:
        """Class bits of every pixel.

        Parameters
        ----------
        image_bgr : ndarray, (H, W, 3) uint8
            BGR pixels (any row stride).
        valid : ndarray, (H, W) uint8, optional
            255 where pixels may be classified, 0 where they never belong to a class.

        Returns
        -------
        list of ndarray, (H, W) uint8
            One plane per 8 classes; bit ``slots[k].bit`` of plane ``slots[k].plane`` is set
            where the pixel is in class ``k``.
        """
        hsv = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2HSV)
        hue = cv2.extractChannel(hsv, 0)
        planes: list[NDArray[np.uint8]] = []
        for (s_lo, v_lo, s_hi, v_hi), luts in self._groups.items():
            window = cv2.inRange(hsv, (0, s_lo, v_lo), (255, s_hi, v_hi))
            if valid is not None:
                window = cv2.bitwise_and(window, valid)
            hue_in = cv2.bitwise_or(hue, cv2.bitwise_not(window))  # 255: no class (hue <= 179)
            for p in range(self.n_planes):
                bits = np.asarray(cv2.LUT(hue_in, luts[p]), np.uint8)
                if len(planes) <= p:
                    planes.append(bits)
                else:
                    planes[p] = np.bitwise_or(planes[p], bits)
        return planes
