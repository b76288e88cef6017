"""Rows of Rerun archetypes gathered per entity and sent as columns.

``RecordingStream.log`` builds an archetype (every component converted to Arrow, one call per
row); ``send_columns`` converts each component once for many rows. :class:`ColumnBuffer` keeps
the rows of each (entity, archetype) in order and sends them in one call per timeline set: the
recording holds the same rows, with the same values at the same times, as one ``log`` call per
row with Rerun's automatic ``log_time`` and ``log_tick`` turned off (the automatic ``log_time``
would put the wall clock on the timeline of that name, which here is the log's own time).

Line strips are converted here (one flat point array and the strip lengths) rather than by
Rerun's converter, which builds an Arrow array per strip.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cache
from typing import Any

import numpy as np
import pyarrow as pa
import rerun as rr
from numpy.typing import NDArray

#: timeline of the log's own time (when the recorder wrote the message)
LOG_TIME = "log_time"
#: timeline of the movement index
MOVEMENT = "movement"


@dataclass(frozen=True)
class Strips:
    """Line strips of one row: their points one after the other.

    Attributes
    ----------
    points : ndarray (P, 2)
        Every strip's points, strip after strip (the entity's frame and unit).
    lengths : ndarray (S,)
        Points in each strip (they sum to P).
    """

    points: NDArray[np.float64]
    lengths: NDArray[np.int64]

    @classmethod
    def of(cls, strips: Sequence[NDArray[np.float64]] | NDArray[np.float64]) -> Strips:
        """Strips from a sequence of (k_i, 2) arrays, or from one (S, k, 2) array."""
        if isinstance(strips, np.ndarray):
            count, k = strips.shape[:2]
            return cls(strips.reshape(-1, 2), np.full(count, k, np.int64))
        lengths = np.array([len(s) for s in strips], np.int64)
        points = np.concatenate(strips) if len(strips) else np.zeros((0, 2))
        return cls(points.reshape(-1, 2), lengths)

    def __len__(self) -> int:
        return len(self.lengths)


@cache
def _strip_type() -> pa.DataType:
    """Arrow type of Rerun's ``LineStrip2D`` component (a list of float32 pairs)."""
    return rr.components.LineStrip2DBatch([]).as_arrow_array().type


def strips_array(strips: Strips) -> pa.Array:
    """``strips`` as the Arrow array of Rerun's ``LineStrip2D`` component (one per strip)."""
    strip_type = _strip_type()
    point_type = strip_type.value_type
    flat = pa.array(np.ascontiguousarray(strips.points, np.float32).ravel(), pa.float32())
    offsets = np.concatenate([[0], np.cumsum(strips.lengths)]).astype(np.int32)
    points = pa.FixedSizeListArray.from_arrays(flat, type=point_type)
    return pa.ListArray.from_arrays(pa.array(offsets), points, type=strip_type)


def _joined(values: list[Any]) -> Any:
    """One field's per-row batches joined into a single batch."""
    if isinstance(values[0], Strips):
        points = np.concatenate([v.points for v in values])
        return strips_array(Strips(points, np.concatenate([v.lengths for v in values])))
    if isinstance(values[0], np.ndarray):
        return np.concatenate(values)
    return [x for v in values for x in v]


@dataclass
class _Rows:
    """The rows of one (entity, archetype): the fields' names, and each row's times and
    batches (in the names' order)."""

    names: tuple[str, ...]
    log_time_ns: list[int] = field(default_factory=list)
    movement: list[int | None] = field(default_factory=list)
    values: list[tuple[Any, ...]] = field(default_factory=list)


class ColumnBuffer:
    """Archetype rows gathered per entity, sent with :meth:`send` as columns.

    A row's fields are given as batches (a sequence or array per component, as to the
    archetype's constructor: ``colors=[rgb]`` for one colour); line strips as :class:`Strips`.
    Every row of an (entity, archetype) must give the same fields.
    """

    def __init__(self) -> None:
        self._rows: dict[tuple[str, type[rr.AsComponents]], _Rows] = {}

    def __len__(self) -> int:
        return sum(len(r.log_time_ns) for r in self._rows.values())

    def add(
        self,
        entity: str,
        log_time_ns: int,
        movement: int | None,
        archetype: type[rr.AsComponents],
        **fields: Any,
    ) -> None:
        """One row of ``archetype`` on ``entity`` at ``log_time_ns`` (and ``movement``)."""
        rows = self._rows.get((entity, archetype))
        if rows is None:
            rows = self._rows[entity, archetype] = _Rows(tuple(fields))
        elif tuple(fields) != rows.names:
            raise ValueError(f"{entity}: rows of {archetype.__name__} with other fields")
        rows.log_time_ns.append(log_time_ns)
        rows.movement.append(movement)
        rows.values.append(tuple(fields.values()))

    def send(self, rec: rr.RecordingStream) -> None:
        """Send every row gathered, in order per entity, and start again."""
        for (entity, archetype), rows in self._rows.items():
            for index, times in _timed(rows):
                columns: list[rr.ComponentColumn] = []
                for k, name in enumerate(rows.names):
                    picked = [rows.values[i][k] for i in index]
                    batch = archetype.columns(**{name: _joined(picked)})  # type: ignore[attr-defined]
                    columns.extend(batch.partition([len(v) for v in picked]))
                rec.send_columns(entity, indexes=times, columns=columns)
        self._rows = {}


def _timed(rows: _Rows) -> list[tuple[list[int], list[rr.TimeColumn]]]:
    """Row indices with a movement (both timelines) and without (log time only)."""
    out = []
    key = [i for i, m in enumerate(rows.movement) if m is not None]
    other = [i for i, m in enumerate(rows.movement) if m is None]
    for index in (key, other):
        if not index:
            continue
        ns = np.array([rows.log_time_ns[i] for i in index], np.int64)
        times = [rr.TimeColumn(LOG_TIME, timestamp=ns.astype("datetime64[ns]"))]
        if index is key:
            movement = np.array([rows.movement[i] for i in index], np.int64)
            times.append(rr.TimeColumn(MOVEMENT, sequence=movement))
        out.append((index, times))
    return out
