"""Text tables with line numbers: every bad cell is reported as ``file:line: what is wrong``.

Fields are separated by commas if a line has any, else by white space; blank lines and lines
starting with ``#`` are skipped. Times are read exactly (decimal seconds to integer ns).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from pathlib import Path

from replay.importers.source import ImportSourceError

NS_PER_S = Decimal(1_000_000_000)


@dataclass(frozen=True)
class Row:
    """One data line of a table: its 1-based line number and its fields."""

    path: Path
    line: int
    fields: list[str]

    def where(self) -> str:
        """``file:line`` for messages."""
        return f"{self.path}:{self.line}"

    def fail(self, problem: str) -> ImportSourceError:
        """The error for this row (one line, with the file and line number)."""
        return ImportSourceError(f"{self.where()}: {problem}")

    def number(self, i: int, column: str) -> float:
        """Field ``i`` as a finite float."""
        text = self.fields[i]
        try:
            value = float(text)
        except ValueError:
            raise self.fail(f"{column} is {text!r}, not a number") from None
        if not math.isfinite(value):
            raise self.fail(f"{column} is {text!r}, not a finite number")
        return value

    def integer(self, i: int, column: str) -> int:
        """Field ``i`` as an integer (``5`` or ``5.0``)."""
        value = self.number(i, column)
        if not value.is_integer():
            raise self.fail(f"{column} is {self.fields[i]!r}, not a whole number")
        return int(value)

    def time_ns(self, i: int, column: str = "t_s") -> int:
        """Field ``i``, decimal seconds >= 0, as integer nanoseconds (exact, rounded to 1 ns)."""
        text = self.fields[i]
        try:
            seconds = Decimal(text)
        except InvalidOperation:
            raise self.fail(f"{column} is {text!r}, not a time in seconds") from None
        if not seconds.is_finite() or seconds < 0:
            raise self.fail(f"{column} is {text!r}; times are seconds >= 0")
        return int((seconds * NS_PER_S).to_integral_value())


def rows(path: Path, *, what: str) -> Iterator[Row]:
    """The data lines of a text table (see module docstring), in file order."""
    try:
        stream = path.open(encoding="utf-8")
    except FileNotFoundError:
        raise ImportSourceError(f"{what} file {path} does not exist") from None
    except OSError as exc:
        raise ImportSourceError(f"cannot read {what} file {path}: {exc.strerror or exc}") from None
    with stream:
        try:
            for number, line in enumerate(stream, start=1):
                text = line.strip()
                if not text or text.startswith("#"):
                    continue
                cells = text.split(",") if "," in text else text.split()
                yield Row(path, number, [c.strip() for c in cells])
        except UnicodeDecodeError:
            raise ImportSourceError(f"{what} file {path} is not UTF-8 text") from None


def with_columns(
    table: Iterator[Row], required: Sequence[str], optional: Sequence[str] = ()
) -> tuple[dict[str, int], Iterator[Row]]:
    """Read a header line naming the columns; return column -> index and the data rows.

    Every row must have one field per column (an optional column's field may be empty).

    Raises
    ------
    ImportSourceError
        No header, a missing or unknown column, or a row with the wrong number of fields.
    """
    header = next(table, None)
    if header is None:
        raise ImportSourceError("empty table: expected a header line naming the columns")
    names = header.fields
    wanted = f"columns {','.join(required)}" + "".join(f"[,{c}]" for c in optional)
    unknown = [n for n in names if n not in (*required, *optional)]
    missing = [n for n in required if n not in names]
    if unknown or missing or len(set(names)) != len(names):
        problem = (
            f"unknown column {unknown[0]!r}"
            if unknown
            else (f"missing column {missing[0]!r}" if missing else "a column is named twice")
        )
        raise header.fail(f"header {','.join(names)!r}: {problem}; expected {wanted}")
    index = {n: i for i, n in enumerate(names)}

    def checked() -> Iterator[Row]:
        for row in table:
            if len(row.fields) != len(names):
                raise row.fail(
                    f"{len(row.fields)} fields, expected {len(names)} ({','.join(names)})"
                )
            yield row

    return index, checked()
