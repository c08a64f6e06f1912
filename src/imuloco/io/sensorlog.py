"""Sensor log files: the CSV exports of phones and of imuloco itself.

Every reader returns :class:`Stream` objects (one tri-axial signal each, timestamps as the file
has them, converted to seconds) and leaves sorting, de-duplication, unit detection, alignment
and resampling to :mod:`imuloco.sensors.reallog`. Supported layouts:

``generic`` (what ``imuloco simulate`` writes), comma separated, one header line::

    time_s,acc_x,acc_y,acc_z,gyro_x,gyro_y,gyro_z

  seconds, specific force in m/s^2 and angular velocity in rad/s, sensor frame. Several sensors
  share one file by prefixing the placement to each signal column
  (``time_s,right_ankle.acc_x,...,right_ankle.gyro_z,pelvis.acc_x,...``); lines starting with
  ``#`` are comments.
``realworld`` — the RealWorld HAR dataset (Sztyler and Stuckenschmidt 2016) as in
  ``shared/data/realworld-shin``: separate accelerometer and gyroscope files with columns
  ``id,attr_time,attr_x,attr_y,attr_z`` (Unix milliseconds; m/s^2 with gravity, rad/s).
``phyphox`` — phyphox (RWTH Aachen) CSV exports: "Acceleration with g" and "Gyroscope"
  (``"Time (s)","Acceleration x (m/s^2)",...`` and ``"Time (s)","Gyroscope x (rad/s)",...``,
  usually ``Raw Data.csv`` in the exported zip), or one table with both (a custom experiment's
  export, where the gyroscope has its own time column or shares the first one). Comma, tab or
  semicolon separators; the semicolon export uses decimal commas. "Linear Acceleration"
  (without g) is refused: the sensor's attitude is lost without gravity.
``sensorlogger`` — a Sensor Logger (Kelvin Choi) zip-CSV export (the zip or its folder): ``TotalAcceleration.csv``
  (with gravity) or ``Accelerometer.csv`` (without gravity) plus ``Gravity.csv``, and
  ``Gyroscope.csv``; columns ``time,seconds_elapsed,z,y,x`` (``time`` in Unix ns), m/s^2 and
  rad/s. iOS reports acceleration with the opposite sign (awesome-sensor-logger COORDINATES.md);
  the platform is read from ``Metadata.csv`` unless given, and guessed with a warning when the
  export has none (:func:`sensorlogger_platform`).

``xsens`` — Xsens text exports (MT Manager, the DOT app, ipol-gait's files), read by
  :mod:`imuloco.io.xsens` with this module's table reader.

phyphox and Sensor Logger exports are read from the zip the app shares as well as from its
unzipped folder (:class:`Export`; members are size-checked before they are decompressed; a
zip's tables must lie in one folder, as two phones' exports zipped together are not one
recording; a folder's files are read only where they resolve to within it, never through a
link out of it). Errors quote at most one cell of a file (:func:`imuloco.errors.excerpt`).
"""

from __future__ import annotations

import csv
import io
import logging
import math
import re
import warnings
import zipfile
import zlib
from array import array
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO, Self

import numpy as np

from imuloco.errors import FormatError, UnknownNameError, excerpt, excerpts
from imuloco.io.atomic import atomic_write, check_output

log = logging.getLogger(__name__)

GENERIC_COLUMNS = ("acc_x", "acc_y", "acc_z", "gyro_x", "gyro_y", "gyro_z")


@dataclass(eq=False)
class Stream:
    """One tri-axial signal as a file holds it.

    Attributes
    ----------
    path : the file it came from (for error messages and reports).
    quantity : ``"acc"`` (specific force, gravity included) or ``"gyro"``.
    times : ndarray, shape (N,), seconds, in file order (not necessarily sorted).
    values : ndarray, shape (N, 3), x, y, z in the phone's axes.
    unit : the unit the format declares (``"m/s^2"``, ``"g"``, ``"rad/s"``, ``"deg/s"``) or
        ``None`` when the format leaves it open and it must be detected.
    placement : body placement named in the file, or ``None``.
    lines : ndarray, shape (N,), 1-based line number of each sample in ``path``.
    platform : Sensor Logger: the platform whose sign convention was applied, and how it was
        found (``"ios (Metadata.csv)"``).
    """

    path: Path
    quantity: str
    times: np.ndarray
    values: np.ndarray
    unit: str | None = None
    placement: str | None = None
    lines: np.ndarray | None = None
    platform: str | None = None


# ---------------------------------------------------------------------------------------------
# table reading with line numbers. The error must name the file, line and column of a bad cell,
# and every limit below must hold while reading (a line without end, a billion rows,
# undecodable bytes), which neither numpy.loadtxt nor pandas reports. So the table is read in
# blocks of lines: a block that numpy.loadtxt reads as a clean (rows, columns) array of numbers
# within the limits is taken as it is (the fast path, ~10x the line loop), any other block is
# read again line by line (hand-written: that reading names the line and column at fault, or
# reads what loadtxt does not: blank lines, comments, quoted or empty cells).

MAX_LINE_BYTES = 1 << 16  # longer lines are refused: no CSV export has lines of 64 KiB
MAX_ROWS = 50_000_000  # ~28 h at 500 Hz; beyond that the table alone would take > 2.8 GB
MAX_CELL = 1e20  # above any timestamp (Unix ns are ~1.7e18) or sensor value; larger is garbage
# blank and comment lines looked through for a table's header: exports have none or a few
# (a zip member of 64 MiB of line breaks was looked through line by line for 105 s)
MAX_PREAMBLE_LINES = 1_000


def _sniff(header: str) -> tuple[str, bool]:
    """Delimiter and whether decimals use commas, from the header line."""
    if "\t" in header:
        return "\t", False
    if ";" in header:
        return ";", True
    return ",", False


def _text_lines(path: Path, f: BinaryIO, first: int = 1) -> Iterator[tuple[int, str]]:
    """(1-based line number, text) of each line of ``f`` (whose first line is line ``first``
    of ``path``), decoded as UTF-8 line by line so that an undecodable byte is reported on its
    own line."""
    for i, raw in enumerate(iter(lambda: f.readline(MAX_LINE_BYTES + 1), b""), first):
        if len(raw) > MAX_LINE_BYTES:
            raise FormatError(path, i, f"line longer than {MAX_LINE_BYTES} bytes: not a sensor "
                                       "log table")
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise FormatError(path, i, f"not UTF-8 text (byte {exc.start + 1} of the line: "
                                       f"{exc.reason})") from None
        yield i, (text.removeprefix("\ufeff") if i == 1 else text).rstrip("\r\n")


def _header_line(path: Path, f: BinaryIO, skip: int = 0) -> tuple[int, str] | None:
    """(line number, text) of the first line of ``f`` after the first ``skip`` that is neither
    blank nor a ``#`` comment; None when the file ends first. FormatError when more than
    :data:`MAX_PREAMBLE_LINES` such lines come first."""
    for i, ln in _text_lines(path, f):
        if i > skip and ln.strip() and not ln.startswith("#"):
            return i, ln
        if i > skip + MAX_PREAMBLE_LINES:
            raise FormatError(path, i, f"no header in the first {MAX_PREAMBLE_LINES:,} lines "
                                       "(blank or comments): not a sensor log table")
    return None


def _split(path: Path, i: int, line: str, delim: str) -> list[str]:
    if '"' not in line and "\0" not in line:
        return line.split(delim)  # the common case, ~5x faster than the csv module
    try:
        return next(csv.reader([line], delimiter=delim))
    except csv.Error as exc:
        raise FormatError(path, i, f"malformed CSV line ({exc})") from None


def _read_table(path: Path, allow_empty: bool = False, data: BinaryIO | None = None,
                skip: int = 0) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Header names, values (N, C) float and the 1-based line of each row.

    Skips blank lines and ``#`` comments, and the first ``skip`` lines (a preamble before the
    header). Empty cells become NaN when ``allow_empty``; other cells must be finite numbers of
    magnitude at most :data:`MAX_CELL`. ``data`` reads from an open binary file (a zip member,
    closed here) instead of ``path``, which then only names it in errors.
    """
    path = Path(path)
    try:
        header, values, rows, start = _parse(path, allow_empty, data, skip)
    except (zipfile.BadZipFile, zlib.error, EOFError) as exc:
        raise FormatError(path, None, f"corrupted zip member ({exc})") from None
    except OSError as exc:
        if data is None:  # the file itself: not found, no permission, ...
            raise
        raise FormatError(path, None, f"corrupted zip member ({exc})") from None
    if not rows:
        raise FormatError(path, start, "no data rows after the header")
    table = np.frombuffer(values, dtype=np.float64).reshape(len(rows), len(header))
    return header, table, np.frombuffer(rows, dtype=np.int64)


BLOCK_BYTES = 1 << 22  # lines read per block by the fast path: ~60,000 rows of a phone log


def _parse(path: Path, allow_empty: bool, data: BinaryIO | None, skip: int = 0
           ) -> tuple[list[str], array, array, int]:
    with (open(path, "rb") if data is None else data) as f:
        start, head = _header_line(path, f, skip) or (None, "")
        if start is None:
            raise FormatError(path, None, "empty file: expected a header line")
        delim, decimal_comma = _sniff(head)
        header = [h.strip() for h in _split(path, start, head, delim)]
        values, rows = array("d"), array("q")
        for first, block in _blocks(f, start + 1):
            if not _fast_block(block, first, len(header), delim, decimal_comma, values, rows):
                _parse_lines(path, _text_lines(path, io.BytesIO(block), first), header, delim,
                             decimal_comma, allow_empty, values, rows)
    return header, values, rows, start


def _blocks(f: BinaryIO, line: int) -> Iterator[tuple[int, bytes]]:
    """(number of its first line, bytes) of consecutive blocks of whole lines of ``f`` from
    line ``line`` on, about :data:`BLOCK_BYTES` each (a block ends at a line break, or at the
    end of the file; a line without end comes as a block over :data:`MAX_LINE_BYTES`)."""
    rest = b""
    while True:
        chunk = f.read(BLOCK_BYTES)
        if not chunk:
            if rest:
                yield line, rest
            return
        rest += chunk
        end = rest.rfind(b"\n") + 1
        if end == 0 and len(rest) <= MAX_LINE_BYTES:
            continue
        end = end or len(rest)  # a line without end: the line reading refuses it
        yield line, rest[:end]
        line += rest.count(b"\n", 0, end)
        rest = rest[end:]


def _fast_block(block: bytes, first: int, width: int, delim: str, decimal_comma: bool,
                values: array, rows: array) -> bool:
    """Append the rows of ``block`` (lines ``first``...) to ``values`` and ``rows`` when it is
    plain: UTF-8 lines of ``width`` numbers within :data:`MAX_CELL` and no longer than
    :data:`MAX_LINE_BYTES` or empty lines, no comment or quote, within :data:`MAX_ROWS` rows
    in all. False (nothing appended) otherwise."""
    if not block.strip():  # blank lines only (a zip bomb's line breaks): nothing to read
        return True
    if b'"' in block or b"\0" in block or b"#" in block:
        return False
    codes = np.frombuffer(block, dtype=np.uint8)
    breaks = np.flatnonzero(codes == 10)
    ends = np.append(breaks, len(codes)) if block[-1:] != b"\n" else breaks
    lengths = np.diff(ends, prepend=-1) - 1  # (lines,) bytes before each line's break
    if lengths.max(initial=0) >= MAX_LINE_BYTES:
        return False  # perhaps a line too long: the line reading says
    # empty lines ("" or "\r") are skipped here too (numpy skips them): runs of line breaks
    # (a zip bomb's) are not read line by line
    full = np.flatnonzero((lengths > 1) | ((lengths == 1) & (codes[ends - 1] != 13)))
    if not len(full):
        return True
    if len(rows) + len(full) > MAX_ROWS:
        return False  # the line reading says where
    try:
        text = block.decode("utf-8")
    except UnicodeDecodeError:
        return False
    if "\r" in text:
        text = text.replace("\r\n", "\n")
        if "\r" in text:
            return False
    if decimal_comma:
        text = text.replace(",", ".")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy warns of an empty block
        try:
            table = np.loadtxt(io.StringIO(text), dtype=np.float64, delimiter=delim,
                               comments=None, ndmin=2)
        except (ValueError, Warning):
            return False
    if table.shape != (len(full), width) or not np.all(np.abs(table) <= MAX_CELL):
        return False  # lines of spaces left out, or NaN, inf or a huge cell (NaN fails too)
    values.frombytes(table.tobytes())
    rows.frombytes((first + full).astype(np.int64).tobytes())
    return True


def _parse_lines(path: Path, lines: Iterator[tuple[int, str]], header: list[str], delim: str,
                 decimal_comma: bool, allow_empty: bool, values: array, rows: array) -> None:
    """Append the values of data ``lines`` (line number, text) to ``values`` and their line
    numbers to ``rows``, line by line; FormatError naming the line and column at fault."""
    for i, ln in lines:
        if not ln.strip() or ln.startswith("#"):
            continue
        if len(rows) >= MAX_ROWS:
            raise FormatError(path, i, f"more than {MAX_ROWS:,} rows: split the recording")
        cells = _split(path, i, ln, delim)
        if len(cells) != len(header):
            raise FormatError(path, i, f"expected {len(header)} values for columns "
                                       f"{','.join(header)}, got {len(cells)}")
        for name, cell in zip(header, cells):
            values.append(_number(path, i, name, cell, decimal_comma, allow_empty))
        rows.append(i)


def _number(path: Path, line: int, name: str, cell: str, decimal_comma: bool,
            allow_empty: bool) -> float:
    cell = cell.strip()
    if decimal_comma:
        cell = cell.replace(",", ".")
    if not cell and allow_empty:
        return math.nan
    try:
        v = float(cell)
    except ValueError:
        raise FormatError(path, line, f"column {excerpt(name)}: expected a number, got "
                                      f"{excerpt(cell)}") from None
    if not abs(v) <= MAX_CELL:  # also catches NaN and inf
        raise FormatError(path, line, f"column {excerpt(name)}: expected a finite number of "
                                      f"magnitude at most {MAX_CELL:g}, got {excerpt(cell)}")
    return v


def _columns(path: Path, header: list[str], wanted: list[str]) -> list[int]:
    missing = [w for w in wanted if w not in header]
    if missing:
        raise FormatError(path, 1, f"missing column(s) {missing}; expected {wanted}, "
                                   f"found {excerpts(header)}")
    return [header.index(w) for w in wanted]


# ---------------------------------------------------------------------------------------------
# generic

COLUMN_NAMES = ("time", *GENERIC_COLUMNS)  # what --columns maps (time: the time column)


def parse_columns(text: str) -> dict[str, str]:
    """``"time=timestamp,acc_x=ax,..."`` as ``{"time": "timestamp", "acc_x": "ax", ...}``
    (:data:`COLUMN_NAMES` to a file's header names); UnknownNameError for anything else."""
    out: dict[str, str] = {}
    for item in filter(None, (i.strip() for i in text.split(","))):
        ours, sep, theirs = (p.strip() for p in item.partition("="))
        ours = "time" if ours == "time_s" else ours
        if not sep or not theirs or ours not in COLUMN_NAMES or ours in out:
            raise UnknownNameError(f"column mapping {item!r}: expected NAME=COLUMN once per "
                                   f"NAME of {list(COLUMN_NAMES)}, e.g. "
                                   "time=timestamp,acc_x=ax,...")
        out[ours] = theirs
    return out


def read_generic_csv(path: str | Path, columns: dict[str, str] | None = None) -> list[Stream]:
    """Streams of a generic CSV (see the module docstring): one acc and one gyro per sensor;
    ``placement`` is the column prefix or ``None`` for the unprefixed single-sensor layout.

    columns : another CSV's own header names for :data:`COLUMN_NAMES` (:func:`parse_columns`;
        unnamed ones keep their generic name): one sensor in those columns, the file's other
        columns ignored, the time column's unit detected as for any log."""
    path = Path(path)
    header, data, lines = _read_table(path)
    if columns:
        wanted = {**{n: n for n in COLUMN_NAMES}, "time": "time_s", **columns}
        idx = _columns(path, header, [wanted[n] for n in COLUMN_NAMES])
        header, data = ["time_s", *GENERIC_COLUMNS], data[:, idx]
    if not header or header[0] != "time_s":
        raise FormatError(path, 1, f"expected first column 'time_s', found {excerpts(header[:1])}")
    names = header[1:]
    if names == list(GENERIC_COLUMNS):
        prefixes: list[str | None] = [None]
    else:
        prefixes = []
        for n in names:
            p = n.rsplit(".", 1)[0] if "." in n else None
            if p is None or n.rsplit(".", 1)[1] not in GENERIC_COLUMNS:
                raise FormatError(path, 1, f"unexpected column {excerpt(n)}: expected "
                                           f"{','.join(GENERIC_COLUMNS)} or "
                                           f"PLACEMENT.{{{','.join(GENERIC_COLUMNS)}}}")
            if p not in prefixes:
                prefixes.append(p)
    out = []
    for p in prefixes:
        cols = [c if p is None else f"{p}.{c}" for c in GENERIC_COLUMNS]
        idx = _columns(path, header, ["time_s"] + cols)
        for q, sl in (("acc", idx[1:4]), ("gyro", idx[4:7])):
            out.append(Stream(path, q, data[:, 0], data[:, sl], None, p, lines))
    return out


def write_generic_csv(rec, path: str | Path, overwrite: bool = False) -> Path:
    """Write a :class:`~imuloco.core.recording.Recording` as generic CSV (m/s^2, rad/s).

    One sensor gives the plain ``time_s,acc_x,...,gyro_z`` header; several sensors prefix the
    placement (``right_ankle.acc_x``). Refuses to replace a file unless ``overwrite``; writes
    atomically.
    """
    path = check_output(path, overwrite)
    if rec.acc.shape[1] == 1:
        cols = list(GENERIC_COLUMNS)
    else:
        cols = [f"{p}.{c}" for p in rec.placements for c in GENERIC_COLUMNS]
    data = np.concatenate([rec.times[:, None], rec.channels()], axis=1)
    with atomic_write(path, "w") as f:
        np.savetxt(f, data, delimiter=",", header=",".join(["time_s"] + cols), comments="",
                   fmt=[f"%.{_time_decimals(rec.times)}f"] + ["%.9g"] * (data.shape[1] - 1))
    return path


def _time_decimals(times: np.ndarray) -> int:
    """Decimals of written timestamps: 6 (microseconds), or up to 9 where fewer would write
    two increasing timestamps as equal (a jittered log of several kHz)."""
    steps = np.diff(times)
    for decimals in range(6, 9):
        # steps over one unit of the last decimal cannot round to equal times (the quick test);
        # shorter ones are checked as written
        if np.all(steps > 1.001 * 10.0**-decimals) or np.all(
                np.diff(np.char.mod(f"%.{decimals}f", times).astype(float)) > 0):
            return decimals
    return 9


# ---------------------------------------------------------------------------------------------
# RealWorld HAR

def read_realworld(acc_path: str | Path, gyro_path: str | Path) -> list[Stream]:
    """The accelerometer and gyroscope files of a RealWorld HAR recording
    (``id,attr_time,attr_x,attr_y,attr_z``, Unix ms)."""
    out = []
    for q, p in (("acc", Path(acc_path)), ("gyro", Path(gyro_path))):
        header, data, lines = _read_table(p)
        idx = _columns(p, header, ["attr_time", "attr_x", "attr_y", "attr_z"])
        out.append(Stream(p, q, data[:, idx[0]] / 1e3, data[:, idx[1:]], None, None, lines))
    return out


# ---------------------------------------------------------------------------------------------
# phyphox

_PHYPHOX = re.compile(r"^(acceleration|linear acceleration|gyroscope) ([xyz]) \((.+)\)$", re.IGNORECASE)
# a simple experiment's table names an axis only ("X (m/s^2)"): its unit and the file's name
# ("Accelerometer.csv", "linearAccelerometer.csv", "Gyroscope.csv") say the quantity
_PHYPHOX_AXIS = re.compile(r"^([xyz]) \((.+)\)$", re.IGNORECASE)
_UNITS = {"m/s^2": "m/s^2", "m/s²": "m/s^2", "g": "g", "rad/s": "rad/s", "deg/s": "deg/s",
          "°/s": "deg/s"}


def _phyphox_column(header: str, file_name: str) -> tuple[str, str, str] | None:
    """(quantity, axis, unit) of a phyphox column: ``"Acceleration x (m/s^2)"``, or a simple
    experiment's ``"X (m/s^2)"`` whose unit and file (``Accelerometer.csv``,
    ``linearAccelerometer.csv``, ``Gyroscope.csv``) say the quantity; None for other
    columns (time, magnitudes, a magnetometer's)."""
    m = _PHYPHOX.match(header)
    if m:
        return m.group(1).lower(), m.group(2).lower(), m.group(3).strip()
    m = _PHYPHOX_AXIS.match(header)
    unit = _UNITS.get(m.group(2).strip()) if m else None
    if unit is None:
        return None
    kind = ("gyroscope" if unit in ("rad/s", "deg/s") else
            "linear acceleration" if "linear" in file_name.lower() else "acceleration")
    return kind, m.group(1).lower(), m.group(2).strip()


def read_phyphox(path: str | Path, data: BinaryIO | None = None) -> list[Stream]:
    """A phyphox CSV export: acceleration with g, gyroscope, or both in one table.

    Each signal takes the nearest ``Time (s)`` column to its left, so tables with one time
    column per sensor and tables with one shared time column both read.
    """
    path = Path(path)
    header, data, lines = _read_table(path, True, data)
    found: dict[str, dict[str, int]] = {}
    units: dict[str, dict[str, str]] = {}  # per signal, the unit of each column
    times: dict[str, int] = {}
    last_time = None
    for i, h in enumerate(header):
        if h.lower().startswith("time (s)"):
            last_time = i
            continue
        column = _phyphox_column(h, path.name)
        if column is None:
            continue
        kind, axis, unit_text = column
        if kind == "linear acceleration":
            raise FormatError(path, 1, f"column {h!r} is acceleration without gravity; export "
                                       "'Acceleration with g' (in a simple experiment: "
                                       "'Accelerometer') instead")
        q = "acc" if kind == "acceleration" else "gyro"
        unit = _UNITS.get(unit_text)
        if unit is None:
            raise FormatError(path, 1, f"column {excerpt(h)}: unknown unit; expected "
                                       f"one of {sorted(set(_UNITS))}")
        if last_time is None:
            raise FormatError(path, 1, f"column {excerpt(h)} has no 'Time (s)' column before it")
        found.setdefault(q, {})[axis] = i
        units.setdefault(q, {})[h] = unit
        times[q] = last_time
    if not found:
        raise FormatError(path, 1, "expected phyphox columns 'Time (s)', 'Acceleration x "
                                   f"(m/s^2)'... or 'Gyroscope x (rad/s)'..., found {excerpts(header)}")
    out = []
    for q, axes in found.items():
        if sorted(axes) != ["x", "y", "z"]:
            raise FormatError(path, 1, f"{q}: expected x, y and z columns, found {sorted(axes)}")
        if len(set(units[q].values())) > 1:  # the columns are known names: quoted whole
            raise FormatError(path, 1, f"{q}: the columns mix units ("
                              + ", ".join(f"{h!r} in {u}" for h, u in units[q].items())
                              + "): expected one unit for x, y and z")
        cols = [times[q]] + [axes[a] for a in "xyz"]
        block = data[:, cols]
        ok = ~np.isnan(block).any(axis=1)
        partial = ~ok & ~np.isnan(block).all(axis=1)
        if partial.any():
            raise FormatError(path, int(lines[np.argmax(partial)]),
                              f"{q}: some of columns {[header[c] for c in cols]} are empty")
        unit = next(iter(units[q].values()))
        out.append(Stream(path, q, block[ok, 0], block[ok, 1:], unit, None, lines[ok]))
    return out


# ---------------------------------------------------------------------------------------------
# app exports: a folder or the zip the app shares

MAX_MEMBER_BYTES = 4 << 30  # a zip member that decompresses to more is refused unread
# a member over MAX_RATIO_FROM bytes that decompresses to more than MAX_RATIO times its
# compressed size is refused unread: a sensor table's digits compress 3-10 times (a phone at
# rest: about 20), a zip bomb's repeated bytes thousands of times (203 bytes of bzip2 were
# 64 MiB of line breaks)
MAX_RATIO, MAX_RATIO_FROM = 100, 1 << 20
MAX_MEMBERS = 10_000


class Export:
    """The files of an app's export (Sensor Logger, phyphox), unzipped in a folder or in the zip
    the app shares, by file name (a zip's sub-folders are looked through, shallowest first)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._zip: zipfile.ZipFile | None = None
        if self.path.is_dir():
            self._members: dict[str, object] = {p.name: p for p in sorted(self.path.iterdir())
                                                 if p.is_file()}
            self._outside = {n for n, p in self._members.items() if not _inside(p, self.path)}
            return
        try:
            self._zip = zipfile.ZipFile(self.path)
            infos = self._zip.infolist()
        except (zipfile.BadZipFile, OSError, EOFError, ValueError, NotImplementedError) as exc:
            raise FormatError(self.path, None, f"not a readable zip archive ({exc})") from None
        if len(infos) > MAX_MEMBERS:
            raise FormatError(self.path, None, f"zip with {len(infos)} members; an app export "
                                               f"has fewer than {MAX_MEMBERS}")
        self._members, self._outside = {}, set()
        for info in sorted(infos, key=lambda i: i.filename.count("/")):
            name = info.filename.rsplit("/", 1)[-1]
            if not info.is_dir() and name and not name.startswith(".") \
                    and "__MACOSX" not in info.filename:
                self._members.setdefault(name, info)
        _one_folder(self.path, infos)

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        if self._zip is not None:
            self._zip.close()

    def names(self) -> list[str]:
        return list(self._members)

    def has(self, name: str) -> bool:
        return name in self._members

    def label(self, name: str) -> Path:
        """The member's path for messages: ``folder/name`` or ``export.zip/sub/name``."""
        m = self._members[name]
        return m if isinstance(m, Path) else self.path / m.filename

    def open(self, name: str) -> BinaryIO:
        m = self._members[name]
        if name in self._outside:
            raise FormatError(self.label(name), None, "a link to a file outside the export "
                                                      "folder: not followed (copy the file in)")
        if isinstance(m, Path):
            return open(m, "rb")
        self._check_size(name)
        try:
            return self._zip.open(m)
        except (zipfile.BadZipFile, zlib.error, EOFError, NotImplementedError, RuntimeError,
                ValueError, OSError) as exc:  # damaged, encrypted or of an unknown compression
            raise FormatError(self.label(name), None, f"unreadable zip member ({exc})") from None

    def _check_size(self, name: str) -> None:
        """Refuse a zip member that unzips to too much (:data:`MAX_MEMBER_BYTES`,
        :data:`MAX_RATIO`), before reading it."""
        m = self._members[name]
        if isinstance(m, Path):
            return
        if m.file_size > MAX_MEMBER_BYTES:
            raise FormatError(self.label(name), None, f"{m.file_size:,} bytes once unzipped, "
                                                      f"more than the {MAX_MEMBER_BYTES:,} allowed")
        if m.file_size > max(MAX_RATIO_FROM, MAX_RATIO * m.compress_size):
            raise FormatError(self.label(name), None, f"{m.compress_size:,} bytes that unzip "
                              f"to {m.file_size:,}, more than {MAX_RATIO} times as many: not a "
                              "sensor table (a zip bomb?)")

    def header(self, name: str) -> str:
        """The first line that is neither blank nor a comment, lower case ('' when none or
        unreadable; a member too large to read is refused)."""
        self._check_size(name)
        try:
            with self.open(name) as f:
                _, line = _header_line(self.label(name), f) or (0, "")
                return line.strip().lower()
        except (FormatError, zipfile.BadZipFile, zlib.error, EOFError, OSError):
            pass
        return ""

    def table(self, name: str, allow_empty: bool = False
              ) -> tuple[list[str], np.ndarray, np.ndarray]:
        return _read_table(self.label(name), allow_empty, self.open(name))

    def is_sensorlogger(self) -> bool:
        """Whether a Sensor Logger table of acceleration or rotation rate is among the files."""
        return any(self.header(n).startswith(_SENSOR_LOGGER_HEADER) for n in _SENSOR_LOGGER_FILES
                   if self.has(n))

    def kind(self) -> str | None:
        """``"sensorlogger"``, ``"phyphox"`` or ``None`` from the members' headers."""
        if self.is_sensorlogger():
            return "sensorlogger"
        if any("time (s)" in self.header(n) for n in self.names() if n.lower().endswith(".csv")):
            return "phyphox"
        return None


def _inside(path: Path, folder: Path) -> bool:
    """Whether ``path`` (a file of ``folder``, perhaps a link) resolves to a file within
    ``folder``: an export is read from its own files, never through a link out of it."""
    try:
        return path.resolve(strict=True).is_relative_to(folder.resolve(strict=True))
    except (OSError, RuntimeError):  # a dangling link, a link loop
        return False


def _one_folder(path: Path, infos: list[zipfile.ZipInfo]) -> None:
    """Refuse a zip whose tables (``.csv`` members, phyphox's ``meta/device.csv`` and
    ``meta/time.csv`` aside) lie in more than one folder: two phones' exports zipped together
    are not one recording."""
    folders: dict[str, str] = {}
    for info in infos:
        folder, _, name = info.filename.rpartition("/")
        meta = folder.rpartition("/")[2] == "meta" and name in _PHYPHOX_META
        if info.is_dir() or not name.lower().endswith(".csv") or name.startswith(".") \
                or "__MACOSX" in folder or meta:
            continue
        folders.setdefault(folder, info.filename)
    if len(folders) > 1:
        shown = ", ".join(list(folders.values())[:4])
        raise FormatError(path, None, f"tables in {len(folders)} folders ({shown}): one "
                                      "recording's export has its tables in one folder; zip "
                                      "each phone's export on its own")


def read_phyphox_export(path: str | Path) -> list[Stream]:
    """Every accelerometer and gyroscope table of a phyphox export (zip or folder)."""
    streams: list[Stream] = []
    refused: FormatError | None = None
    with Export(path) as ex:
        for name in ex.names():
            h = ex.header(name)
            if not name.lower().endswith(".csv") or "time (s)" not in h or not any(
                    _phyphox_column(c.strip().strip('"'), name) for c in re.split(r"[,;\t]", h)):
                continue
            try:
                streams += read_phyphox(ex.label(name), ex.open(name))
            except FormatError as exc:  # linear acceleration: fine if another table has g
                if "without gravity" not in exc.message:
                    raise
                refused = exc
    if refused is not None and not any(s.quantity == "acc" for s in streams):
        raise refused
    if not streams:
        raise FormatError(path, None, "no phyphox table with 'Time (s)' and acceleration or "
                                      "gyroscope columns in the export")
    return streams


_PHYPHOX_META = ("device.csv", "time.csv")  # phyphox writes meta/ with these into every export


def phyphox_members(folder: str | Path) -> set[str]:
    """The files of an unzipped phyphox export in ``folder`` (its tables, with a ``Time (s)``
    column, and the files of its ``meta/`` folder as ``meta/NAME``), which the folder reads as
    one log; none when ``folder`` is no export: one is known by ``meta/device.csv`` or
    ``meta/time.csv``, as several phyphox tables of a folder may be several walkers'."""
    folder = Path(folder)
    meta = folder / "meta"
    if not any((meta / n).is_file() for n in _PHYPHOX_META):
        return set()
    with Export(folder) as ex:
        if ex.kind() != "phyphox":
            return set()
        tables = {n for n in ex.names() if "time (s)" in ex.header(n)}
    return tables | {f"meta/{p.name}" for p in meta.iterdir() if p.is_file()}


# ---------------------------------------------------------------------------------------------
# Sensor Logger

_SENSOR_LOGGER_FILES = ("Gyroscope.csv", "TotalAcceleration.csv", "Accelerometer.csv")
_SENSOR_LOGGER_HEADER = "time,seconds_elapsed"  # every sensor's table starts so
PLATFORMS = ("android", "ios")


def _sensorlogger_file(ex: Export, name: str, quantity: str, unit: str) -> Stream:
    header, data, lines = ex.table(name)
    path = ex.label(name)
    idx = _columns(path, header, ["time", "x", "y", "z"])
    # ``time`` (Unix ns) rather than ``seconds_elapsed``: the same clock in every file, and
    # float64 keeps ~0.2 us at today's epoch, finer than any phone's timestamps.
    return Stream(path, quantity, data[:, idx[0]] * 1e-9, data[:, idx[1:]], unit, None, lines)


def sensorlogger_platform(ex: Export) -> tuple[str, str]:
    """The export's platform and how it was found.

    ``Metadata.csv`` says it (``"ios"`` only when "Standardise Units & Frames" was off: on iOS
    acceleration then has the opposite sign, awesome-sensor-logger CROSSPLATFORM.md). Without
    it the platform is guessed, with a warning: ``AccelerometerUncalibrated.csv`` is in g on
    iOS and in m/s^2 on Android (UNITS.md), so its median magnitude tells them apart; when
    that file is missing too, Android is assumed. Acceleration and angular velocity alone
    cannot tell: negating the acceleration is a mirror image of a possible movement.
    """
    if ex.has("Metadata.csv"):
        try:
            with ex.open("Metadata.csv") as f:
                text = f.read(MAX_LINE_BYTES).decode("utf-8-sig", errors="replace")
        except (zipfile.BadZipFile, zlib.error, EOFError, OSError) as exc:
            raise FormatError(ex.label("Metadata.csv"), None, f"corrupted zip member ({exc})"
                              ) from None
        rows = list(csv.DictReader(text.splitlines()))
        if rows:
            row = {k.strip().lower(): (v or "").strip().lower()
                   for k, v in rows[0].items() if isinstance(k, str) and isinstance(v, str)}
            standard = any("standardis" in k or "standardiz" in k for k, v in row.items()
                           if v in ("true", "1", "yes"))
            if row.get("platform") in PLATFORMS:
                ios = row["platform"] == "ios" and not standard
                return ("ios" if ios else "android"), "Metadata.csv"
    if ex.has("AccelerometerUncalibrated.csv"):
        _, data = ex.table("AccelerometerUncalibrated.csv")[:2]
        mag = float(np.median(np.linalg.norm(data[:, -3:], axis=1)))
        platform = "ios" if mag < math.sqrt(9.80665) else "android"
        log.warning("%s: no platform in Metadata.csv; guessed %s from AccelerometerUncalibrated"
                    ".csv (median %.2f: %s); pass --platform to say it", ex.path, platform, mag,
                    "g, as iOS writes it" if platform == "ios" else "m/s^2, as Android does")
        return platform, "guessed from AccelerometerUncalibrated.csv"
    log.warning("%s: no Metadata.csv to say whether the phone was an iPhone (whose acceleration "
                "has the opposite sign) or Android; assuming Android: pass --platform ios if it "
                "was an iPhone", ex.path)
    return "android", "assumed (no metadata)"


def read_sensor_logger(folder: str | Path, platform: str | None = None) -> list[Stream]:
    """A Sensor Logger export (a folder or its zip): specific force with gravity and rotation
    rate.

    ``platform``: ``"android"`` or ``"ios"`` (iOS acceleration has the opposite sign); ``None``
    reads it from Metadata.csv or guesses it with a warning (:func:`sensorlogger_platform`).
    The accelerometer stream's ``platform`` says which was used.
    """
    if platform is not None and platform.lower() not in PLATFORMS:
        raise UnknownNameError(f"platform must be one of {list(PLATFORMS)}, got {platform!r}")
    with Export(folder) as ex:
        found = (platform.lower(), "given") if platform else sensorlogger_platform(ex)
        if not ex.has("Gyroscope.csv"):
            raise FormatError(folder, None, "expected Gyroscope.csv in the Sensor Logger export")
        if ex.has("TotalAcceleration.csv"):
            acc = _sensorlogger_file(ex, "TotalAcceleration.csv", "acc", "m/s^2")
        elif ex.has("Accelerometer.csv") and ex.has("Gravity.csv"):
            acc = _sensorlogger_file(ex, "Accelerometer.csv", "acc", "m/s^2")
            g = _sensorlogger_file(ex, "Gravity.csv", "acc", "m/s^2")
            order = np.argsort(g.times, kind="stable")
            acc.values = acc.values + np.stack(
                [np.interp(acc.times, g.times[order], g.values[order, k]) for k in range(3)], 1)
        else:
            raise FormatError(folder, None, "expected TotalAcceleration.csv, or Accelerometer.csv "
                                            "(without gravity) together with Gravity.csv")
        gyro = _sensorlogger_file(ex, "Gyroscope.csv", "gyro", "rad/s")
        watch = read_wrist_motion(ex) if ex.has(WATCH_FILE) else []
    if found[0] == "ios":
        acc.values = -acc.values
    acc.platform = f"{found[0]} ({found[1]})"
    return [acc, gyro, *watch]


WATCH_FILE = "WristMotion.csv"  # an Apple Watch recorded beside the phone, same export
WATCH_PLACEMENT = "left_wrist"  # where the watch is read (a watch is usually worn on the left)
_WATCH_COLUMNS = ["time", "accelerationX", "accelerationY", "accelerationZ",
                  "gravityX", "gravityY", "gravityZ",
                  "rotationRateX", "rotationRateY", "rotationRateZ"]
GRAVITY_SIZE = (0.8, 1.2)  # the watch's gravity magnitude, in its unit (Core Motion's is 1 g)


def read_wrist_motion(ex: Export) -> list[Stream]:
    """The Apple Watch's ``WristMotion.csv`` of a Sensor Logger export, as the streams of a
    sensor at :data:`WATCH_PLACEMENT` (``docs/results/multi/README.md``).

    Its columns (awesome-sensor-logger UNITS.md): ``time`` (Unix ns, the phone's clock),
    ``accelerationX..Z`` (Core Motion's user acceleration, gravity removed) and
    ``gravityX..Z``, both in g, or in m/s^2 when "Standardise Units & Frames" is on,
    ``rotationRateX..Z`` in rad/s (and quaternion, pitch, roll, yaw, not read). Specific force
    is their sum; with the setting off it has the iOS sign (the opposite of Android's and
    imuloco's) and is negated. Which of the two the file holds is read from its gravity's
    median magnitude (1 in g, 9.81 in m/s^2): the unit and the sign come with the one setting,
    so the watch needs no Metadata.csv. Gravity whose median size is not
    :data:`GRAVITY_SIZE` times 1 g is refused.
    """
    header, data, lines = ex.table(WATCH_FILE)
    path = ex.label(WATCH_FILE)
    idx = _columns(path, header, _WATCH_COLUMNS)
    t = data[:, idx[0]] * 1e-9
    user, gravity, rate = data[:, idx[1:4]], data[:, idx[4:7]], data[:, idx[7:10]]
    size = float(np.median(np.linalg.norm(gravity, axis=1)))
    in_g = size < math.sqrt(9.80665)
    if not GRAVITY_SIZE[0] <= size / (1.0 if in_g else 9.80665) <= GRAVITY_SIZE[1]:
        raise FormatError(path, None, f"gravityX..Z: median magnitude {size:.3g}; expected "
                                      "about 1 (g) or 9.81 (m/s^2): Core Motion's gravity")
    acc = -(user + gravity) * 9.80665 if in_g else user + gravity
    return [Stream(path, "acc", t, acc, "m/s^2", WATCH_PLACEMENT, lines,
                   "ios (WristMotion.csv in g)" if in_g else "standardised (WristMotion.csv)"),
            Stream(path, "gyro", t, rate, "rad/s", WATCH_PLACEMENT, lines)]


def sensorlogger_members(folder: str | Path) -> set[str]:
    """The files of an unzipped Sensor Logger export in ``folder`` (its sensors' tables and
    ``Metadata.csv``), which the folder reads as one log; none when ``folder`` is no export."""
    folder = Path(folder)
    if not folder.is_dir():
        return set()
    with Export(folder) as ex:
        if not ex.is_sensorlogger():
            return set()
        return {n for n in ex.names()
                if n == "Metadata.csv" or ex.header(n).startswith(_SENSOR_LOGGER_HEADER)}


def export_members(folder: str | Path) -> set[str]:
    """The files of the unzipped app export (Sensor Logger or phyphox) in ``folder``, which
    the folder reads as one log, as paths relative to it (:func:`sensorlogger_members`,
    :func:`phyphox_members`); none when ``folder`` is no export."""
    return sensorlogger_members(folder) or phyphox_members(folder)


# ---------------------------------------------------------------------------------------------

def is_export(path: str | Path) -> bool:
    """Whether ``path`` is an export folder or a zip (by its signature, even when damaged)."""
    path = Path(path)
    if path.is_dir():
        return True
    with open(path, "rb") as f:
        return f.read(4) == b"PK\x03\x04" or zipfile.is_zipfile(path)
