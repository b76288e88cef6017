"""The joint map's bearings as arrays, so that checking every residual costs numpy, not Python.

One row per bearing of a placed movement whose landmark is in the graph (kept out as rejected
or not): its keyframe slot ``2 movement + end``, its landmark's catalog index, the measured
bearing and whether it is rejected. Rows are only appended or flagged; a change of the set
otherwise (a landmark forgotten, a map rolled back) builds a new table.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable, Mapping, Sequence

import gtsam
import numpy as np
from numpy.typing import NDArray

from data_schemas.angles import wrap_rad
from pipeline.geometry import predicted_bearings
from pipeline.joint import graph as g

_POSE_KEY_0 = g.pose_key(0, 0)
_LANDMARK_KEY_0 = g.landmark_key(0)
#: Keys of one letter share the top byte (gtsam.Symbol: letter << 56 | index).
_INDEX_SPAN = 1 << 56


class BearingTable:
    """Bearings of the map, one row each, with their keyframe slot, landmark and rejection.

    Attributes
    ----------
    rows : list of Bearing
        The bearings, in the order they were added.
    version : int
        Changes with every addition or rejection flag (a residual cache's key).
    """

    def __init__(self) -> None:
        self.rows: list[g.Bearing] = []
        self.version = 0
        self._row_of: dict[g.Bearing, int] = {}
        self._slot = np.zeros(64, np.int64)
        self._landmark = np.zeros(64, np.int64)
        self._bearing_rad = np.zeros(64, np.float64)
        self._rejected = np.zeros(64, np.bool_)

    def __len__(self) -> int:
        return len(self.rows)

    @property
    def slot(self) -> NDArray[np.int64]:
        """Keyframe slot ``2 movement + end`` of each row (n,)."""
        return self._slot[: len(self.rows)]

    @property
    def landmark(self) -> NDArray[np.int64]:
        """Catalog index of each row's landmark (n,)."""
        return self._landmark[: len(self.rows)]

    @property
    def bearing_rad(self) -> NDArray[np.float64]:
        """Measured bearing of each row (n,), rad."""
        return self._bearing_rad[: len(self.rows)]

    @property
    def rejected(self) -> NDArray[np.bool_]:
        """Whether each row is kept out of the graph (n,)."""
        return self._rejected[: len(self.rows)]

    def add(
        self,
        bearings: Iterable[g.Bearing],
        landmark_index: Mapping[str, int],
        rejected: Collection[g.Bearing] = (),
    ) -> None:
        """Append ``bearings`` not in the table yet; those in ``rejected`` flagged so."""
        new = [b for b in bearings if b not in self._row_of]
        if not new:
            return
        n, k = len(self.rows), len(new)
        if n + k > self._slot.size:
            size = max(2 * self._slot.size, n + k)
            self._slot = np.resize(self._slot, size)
            self._landmark = np.resize(self._landmark, size)
            self._bearing_rad = np.resize(self._bearing_rad, size)
            self._rejected = np.resize(self._rejected, size)
        for i, b in enumerate(new, start=n):
            self._row_of[b] = i
            self.rows.append(b)
        self._slot[n : n + k] = [2 * b.movement + b.end for b in new]
        self._landmark[n : n + k] = [landmark_index[b.landmark] for b in new]
        self._bearing_rad[n : n + k] = [b.bearing_rad for b in new]
        self._rejected[n : n + k] = [b in rejected for b in new]
        self.version += 1

    def set_rejected(self, bearings: Iterable[g.Bearing], rejected: bool) -> None:
        """Flag ``bearings`` (rows of the table) rejected or not."""
        rows = [self._row_of[b] for b in bearings]
        if rows:
            self._rejected[rows] = rejected
            self.version += 1

    def subset(self, mask: NDArray[np.bool_]) -> BearingTable:
        """A new table of the rows where ``mask`` (n,) holds, in their order."""
        out = BearingTable()
        rows = np.flatnonzero(mask)
        out.rows = [self.rows[i] for i in rows]
        out._row_of = {b: i for i, b in enumerate(out.rows)}
        out._slot = self.slot[rows]
        out._landmark = self.landmark[rows]
        out._bearing_rad = self.bearing_rad[rows]
        out._rejected = self.rejected[rows]
        out.version = self.version + 1
        return out

    def select(self, mask: NDArray[np.bool_]) -> list[g.Bearing]:
        """The bearings of the rows where ``mask`` (n,) holds."""
        return [self.rows[i] for i in np.flatnonzero(mask)]

    def residuals(self, values: gtsam.Values) -> NDArray[np.float64]:
        """Measured minus predicted bearing (n,), rad, wrapped, at ``values`` (every keyframe
        and landmark of the rows in it)."""
        if not self.rows:
            return np.zeros(0)
        keys = np.asarray(values.keys(), np.int64)
        xyh = _columns_by_index(keys, _POSE_KEY_0, gtsam.utilities.extractPose2(values), self.slot)
        pts = _columns_by_index(
            keys, _LANDMARK_KEY_0, gtsam.utilities.extractPoint2(values), self.landmark
        )
        predicted = predicted_bearings(xyh[:2].T, xyh[2], pts.T)
        return np.asarray(wrap_rad(self.bearing_rad - predicted), np.float64)


def _columns_by_index(
    keys: NDArray[np.int64], key_0: int, rows: NDArray[np.float64], index: NDArray[np.int64]
) -> NDArray[np.float64]:
    """The variables of letter ``key_0`` with symbol indices ``index`` (k,), as columns
    (width, k), from ``rows`` (``gtsam.utilities.extractPose2`` or ``extractPoint2`` of values
    whose every key is in ``keys``, sorted): the variables of that letter come first there, in
    key order (``extractPoint2`` also gives a row for the scale, whose letter comes after ``l``)."""
    own = keys[(keys >= key_0) & (keys < key_0 + _INDEX_SPAN)] - key_0
    row_of = np.zeros(int(own[-1]) + 1 if own.size else 0, np.int64)
    row_of[own] = np.arange(own.size)
    at = row_of[index]
    columns = np.asarray(rows, np.float64)[: own.size].T
    return np.stack([c.take(at) for c in columns])  # by column: fancy rows are 3x slower


def by_landmark(
    table: BearingTable, values: NDArray[np.float64], skip: Sequence[int] = ()
) -> dict[int, NDArray[np.float64]]:
    """``values`` (n,), one per row of ``table``, grouped by landmark index (``skip`` left out)."""
    order = np.argsort(table.landmark, kind="stable")
    lm = table.landmark[order]
    cuts = np.flatnonzero(np.diff(lm)) + 1
    return {
        int(part_lm[0]): values[part]
        for part, part_lm in zip(np.split(order, cuts), np.split(lm, cuts), strict=True)
        if part.size and int(part_lm[0]) not in skip
    }
