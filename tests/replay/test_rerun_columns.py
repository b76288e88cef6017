"""``ColumnBuffer``: rows sent as columns read back as the same rows ``RecordingStream.log`` gives.

The oracle is Rerun's own row API: the same rows are logged one ``log`` call each into a second
recording (its automatic ``log_time`` and ``log_tick`` turned off: the automatic ``log_time``
would replace the timeline of that name with the wall clock), and both files are read back with
Rerun's reader.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pytest
import rerun as rr

from replay.sinks.rerun_columns import LOG_TIME, MOVEMENT, ColumnBuffer, Strips

RED, BLUE = (255, 0, 0), (0, 0, 255)
SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.0, 0.0]])
SEGMENT = np.array([[0.25, -0.5], [2.0, 3.5]])
DOT = np.zeros((1, 2))
PIXELS = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3)
PIXELS_FORMAT = rr.components.ImageFormat(
    width=3, height=2, color_model="BGR", channel_datatype="U8"
)

#: (entity, log time ns, movement, archetype, fields): strips given as lists of (k, 2) arrays
ROWS: list[tuple[str, int, int | None, type[Any], dict[str, Any]]] = [
    ("fr/cones/a", 10, 0, rr.LineStrips2D, {"strips": [SQUARE, SEGMENT], "colors": [RED]}),
    ("fr/cones/a", 20, 1, rr.Clear, {"is_recursive": [False]}),
    ("fr/cones/a", 30, 2, rr.LineStrips2D, {"strips": [SEGMENT, DOT, SQUARE], "colors": [BLUE]}),
    ("fr/cones/a", 40, 3, rr.LineStrips2D, {"strips": [], "colors": [RED]}),
    ("map/points", 10, 0, rr.Points2D, {"positions": SQUARE, "labels": ["p"] * 5}),
    ("map/points", 20, 1, rr.Points2D, {"positions": SEGMENT[:1], "labels": ["q"]}),
    ("log", 10, 0, rr.TextLog, {"text": ["first"], "level": ["INFO"]}),
    ("log", 10, 0, rr.TextLog, {"text": ["second, same time"], "level": ["WARN"]}),
    ("log", 5, None, rr.TextLog, {"text": ["before any movement"], "level": ["INFO"]}),
    ("bearings/a", 7, None, rr.Scalars, {"scalars": [12.5]}),
    ("bearings/a", 10, 0, rr.Scalars, {"scalars": [-3.25]}),
    ("camera", 7, None, rr.EncodedImage, {"blob": [b"\x89PNG one"], "media_type": ["image/png"]}),
    ("camera", 10, 0, rr.EncodedImage, {"blob": [b"\x89PNG two"], "media_type": ["image/png"]}),
    ("raw", 12, 0, rr.Image, {"buffer": [PIXELS.ravel()], "format": [PIXELS_FORMAT]}),
    ("raw", 14, None, rr.Image, {"buffer": [PIXELS[::-1].ravel()], "format": [PIXELS_FORMAT]}),
]


def _read(rrd: Path) -> dict[str, list[tuple[Any, ...]]]:
    """entity -> its rows as (movement, log time, row in the entity, components), in time order.

    Only the two timelines and the components are kept (``rec.log`` adds ``log_tick``).
    """
    rows: dict[str, list[dict[str, Any]]] = {}
    for chunk in rr.chunk.RrdReader(rrd).stream():
        batch = chunk.to_record_batch()
        names = batch.schema.names
        columns = [
            col.cast(pa.int64()) if pa.types.is_timestamp(col.type) else col
            for col in batch.columns
        ]
        for row in pa.RecordBatch.from_arrays(columns, names=names).to_pylist():
            kept = {n: row[n] for n in names if ":" in n and row[n] is not None}
            if row.get(LOG_TIME) is not None and kept:
                kept["_time"] = (row.get(MOVEMENT), row[LOG_TIME])
                rows.setdefault(chunk.entity_path, []).append(kept)
    out = {}
    for entity, found in rows.items():
        # rows at the same times keep their order in the recording (stable sort)
        found.sort(key=lambda r: (-1 if r["_time"][0] is None else r["_time"][0], r["_time"][1]))
        out[entity] = [(*r.pop("_time"), sorted(r.items(), key=lambda kv: kv[0])) for r in found]
    return out


def _by_rows(rrd: Path) -> None:
    rec = rr.RecordingStream("columns-test", recording_id="rows")
    rec.set_log_time_enabled(False)
    rec.set_log_tick_enabled(False)
    rec.save(rrd)
    for entity, ns, movement, archetype, fields in ROWS:
        rec.set_time(LOG_TIME, timestamp=np.datetime64(ns, "ns"))
        if movement is None:
            rec.disable_timeline(MOVEMENT)
        else:
            rec.set_time(MOVEMENT, sequence=movement)
        rec.log(entity, archetype.from_fields(**fields))
    rec.disconnect()


def _by_columns(rrd: Path, sends: int) -> None:
    rec = rr.RecordingStream("columns-test", recording_id="columns")
    rec.save(rrd)
    buffer = ColumnBuffer()
    every = max(1, len(ROWS) // sends)
    for k, (entity, ns, movement, archetype, fields) in enumerate(ROWS):
        given = dict(fields)
        if "strips" in given:
            given["strips"] = Strips.of(given["strips"])
        buffer.add(entity, ns, movement, archetype, **given)
        if (k + 1) % every == 0:
            buffer.send(rec)
    assert len(buffer) == len(ROWS) % every
    buffer.send(rec)
    assert len(buffer) == 0
    rec.disconnect()


@pytest.mark.parametrize("sends", [1, 4])
def test_columns_read_back_as_the_rows_logged_one_by_one(tmp_path: Path, sends: int) -> None:
    _by_rows(tmp_path / "rows.rrd")
    _by_columns(tmp_path / "columns.rrd", sends)
    expected, got = _read(tmp_path / "rows.rrd"), _read(tmp_path / "columns.rrd")
    assert set(got) == set(expected) == {"/" + r[0] for r in ROWS}
    for entity in expected:
        assert got[entity] == expected[entity], entity


def test_a_row_with_other_fields_is_refused() -> None:
    buffer = ColumnBuffer()
    buffer.add("map/points", 0, 0, rr.Points2D, positions=DOT, colors=[RED])
    with pytest.raises(ValueError, match="map/points"):
        buffer.add("map/points", 1, 1, rr.Points2D, positions=DOT)


def test_strips_of_an_array_and_of_a_list_agree() -> None:
    segments = np.arange(24, dtype=np.float64).reshape(3, 4, 2)
    from_array, from_list = Strips.of(segments), Strips.of(list(segments))
    assert len(from_array) == len(from_list) == 3
    np.testing.assert_array_equal(from_array.points, from_list.points)
    np.testing.assert_array_equal(from_array.lengths, [4, 4, 4])
    np.testing.assert_array_equal(from_list.lengths, [4, 4, 4])
    assert len(Strips.of([])) == 0 and Strips.of([]).points.shape == (0, 2)
