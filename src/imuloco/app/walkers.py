"""A study's walkers file (``imuloco batch --walkers``): each walker's height and own columns.

A CSV with a header and one row per walker: ``name``, the walker's output name in the batch
(``NAME.bvh``, ``NAME.json``; see :func:`imuloco.app.batch.output_names`), and ``height_m``,
the body height in metres (an empty cell: the batch's default height). Any other column is the
study's own (age, group, ...): carried into ``summary.csv``, ``summary.json`` and
``walkers.parquet``, as int64 or float64 when every filled cell of the file is one, else as
text. One file can serve all the study's batches: rows of walkers without a recording in this
batch are counted in one warning, and the batch's recordings without a row (the default
height) named in another. A name twice, a bad height, a column clashing with batch's own or a
name matching no recording but close to one without a row (a typo would lose that walker's
height) is a :class:`~imuloco.errors.FormatError` naming the file and line.
"""

from __future__ import annotations

import contextlib
import csv
import difflib
import logging
import math
from collections.abc import Collection, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from imuloco.errors import FormatError
from imuloco.measures.gait import MAX_HEIGHT_M, MIN_HEIGHT_M

log = logging.getLogger(__name__)
NAME, HEIGHT = "name", "height_m"  # the file's own columns
HEIGHT_RANGE_M = (MIN_HEIGHT_M, MAX_HEIGHT_M)  # as imuloco.measures.gait.height_scale takes
NAMED = 3  # recordings without a row named in the warning, then "..."


@dataclass(frozen=True)
class Walkers:
    """What a walkers file says: ``heights`` (metres, walkers with a filled cell only),
    ``fields`` (the study's own columns as pyarrow fields) and ``values`` (per name, the
    study's columns; ``None`` where empty)."""

    heights: dict[str, float] = field(default_factory=dict)
    fields: tuple = ()
    values: dict[str, dict[str, Any]] = field(default_factory=dict)

    def columns(self, name: str) -> dict[str, Any]:
        """The study's columns of walker ``name`` (all ``None`` without a row)."""
        return self.values.get(name) or {f.name: None for f in self.fields}


def read_walkers(path: str | Path, names: Sequence[str], reserved: Collection[str] = ()
                 ) -> Walkers:
    """Read the walkers file ``path`` of a batch whose walkers are ``names``; ``reserved``:
    columns the study's own may not be named (the batch's)."""
    path = Path(path)
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:  # a spreadsheet's BOM
            reader = csv.DictReader(f)
            header = [c.strip() for c in reader.fieldnames or []]
            reader.fieldnames = header
            rows = [(reader.line_num, row) for row in reader]
    except (UnicodeDecodeError, csv.Error) as e:
        raise FormatError(path, None, f"not a CSV file of walkers: {e}") from None
    extra = _check_header(path, header, reserved)
    lines: dict[str, int] = {}
    heights: dict[str, float] = {}
    cells: dict[str, dict[str, str | None]] = {}
    for line, row in rows:
        if None in row:
            raise FormatError(path, line, f"more cells than the header's {len(header)} columns")
        row = {k: (v or "").strip() or None for k, v in row.items()}
        if not any(row.values()):
            continue  # a spreadsheet's empty row
        name = _check_name(path, line, row[NAME], lines)
        lines[name] = line
        if row[HEIGHT] is not None:
            heights[name] = _height(path, line, row[HEIGHT])
        cells[name] = {c: row[c] for c in extra}
    _check_batch(path, lines, names)
    fields, values = _typed(extra, cells)
    return Walkers(heights, fields, values)


def _check_header(path: Path, header: list[str], reserved: Collection[str]) -> list[str]:
    """The study's own columns of ``header``, after checking it."""
    if NAME not in header or HEIGHT not in header:
        raise FormatError(path, 1, f"expected a header with the columns {NAME!r} and "
                                   f"{HEIGHT!r}, found {header}")
    twice = sorted({c for c in header if header.count(c) > 1})
    clash = [c for c in header if c in reserved and c not in (NAME, HEIGHT)]
    if twice or clash or "" in header:
        raise FormatError(path, 1, f"column(s) {twice} appear twice" if twice else
                          "a column has no name" if "" in header else
                          f"column(s) {clash} are batch's own: rename them")
    return [c for c in header if c not in (NAME, HEIGHT)]


def _check_name(path: Path, line: int, name: str | None, lines: dict[str, int]) -> str:
    """``name`` when it is filled and not seen before (``lines``)."""
    if name is None:
        raise FormatError(path, line, f"field {NAME!r}: empty; expected a walker's name")
    if name in lines:
        raise FormatError(path, line, f"name {name!r} is on lines {lines[name]} and {line}")
    return name


def _check_batch(path: Path, lines: dict[str, int], names: Sequence[str]) -> None:
    """Refuse a row (``lines``: name to line) matching none of the batch's ``names`` but close
    to one without a row, a likely typo; warn once of the other rows matching none (walkers of
    other batches) and once of the recordings without a row."""
    batch = set(names)
    rowless = [n for n in names if n not in lines]
    others = [n for n in lines if n not in batch]
    for name in others if rowless else ():
        close = difflib.get_close_matches(name, rowless, n=3)
        if close:
            raise FormatError(path, lines[name], (
                f"name {name!r} matches no recording of the batch (close: "
                f"{', '.join(map(repr, close))}, without a row; a name is the recording's "
                f"output NAME, NAME.bvh; if {name!r} is another walker, give {close[0]!r} a "
                "row too, its height_m empty for the default)"))
    if others:
        log.warning("%s: %d walker%s no recording in this batch", path, len(others),
                    " has" if len(others) == 1 else "s have")
    if rowless:
        shown = ", ".join(rowless[:NAMED]) + (", ..." if len(rowless) > NAMED else "")
        log.warning("%s: no row for %d recording(s) of this batch, which get the default "
                    "height (--height, else the model skeleton's): %s", path, len(rowless),
                    shown)


def _height(path: Path, line: int, cell: str) -> float:
    lo, hi = HEIGHT_RANGE_M
    try:
        value = float(cell)
    except ValueError:
        value = math.nan
    if not lo <= value <= hi:  # also NaN
        cm = " (metres, not centimetres)" if lo * 100 <= value <= hi * 100 else ""
        raise FormatError(path, line, f"field {HEIGHT!r}: {cell!r} is not a body height in "
                                      f"metres; expected {lo:g} to {hi:g}{cm}")
    return value


def _typed(columns: list[str], cells: dict[str, dict[str, str | None]]
           ) -> tuple[tuple, dict[str, dict[str, Any]]]:
    """The columns' pyarrow fields, each int64, float64 or string (the first that every
    filled cell converts to), and the typed values per name."""
    import pyarrow as pa  # the [dist] extra's

    fields, typed = [], {}
    for c in columns:
        array = pa.array([row[c] for row in cells.values()], pa.string())
        for kind in (pa.int64(), pa.float64()):
            with contextlib.suppress(pa.ArrowInvalid):
                array = array.cast(kind)
                break
        fields.append(pa.field(c, array.type))
        typed[c] = array.to_pylist()
    values = {n: {c: typed[c][k] for c in columns} for k, n in enumerate(cells)}
    return tuple(fields), values
