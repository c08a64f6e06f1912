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
``sensorlogger`` — a Sensor Logger (Kelvin Choi) zip-CSV export folder: ``TotalAcceleration.csv``
  (with gravity) or ``Accelerometer.csv`` (without gravity) plus ``Gravity.csv``, and
  ``Gyroscope.csv``; columns ``time,seconds_elapsed,z,y,x`` (``time`` in Unix ns), m/s^2 and
  rad/s. iOS reports acceleration with the opposite sign (awesome-sensor-logger COORDINATES.md);
  the platform is read from ``Metadata.csv`` unless given.
"""

from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from imuloco.errors import FormatError

GENERIC_COLUMNS = ("acc_x", "acc_y", "acc_z", "gyro_x", "gyro_y", "gyro_z")
FORMATS = ("generic", "realworld", "phyphox", "sensorlogger")


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
    """

    path: Path
    quantity: str
    times: np.ndarray
    values: np.ndarray
    unit: str | None = None
    placement: str | None = None
    lines: np.ndarray | None = None


# ---------------------------------------------------------------------------------------------
# table reading with line numbers (csv + float: the error must name the line, which
# numpy.loadtxt does not do in a form we can report)

def _sniff(path: Path, header: str) -> tuple[str, bool]:
    """Delimiter and whether decimals use commas, from the header line."""
    if "\t" in header:
        return "\t", False
    if ";" in header:
        return ";", True
    return ",", False


def _read_table(path: Path, allow_empty: bool = False
                ) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Header names, values (N, C) float and the 1-based line of each row.

    Skips blank lines and ``#`` comments. Empty cells become NaN when ``allow_empty``.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise FormatError(path, None, f"not a UTF-8 text file ({exc.reason})") from None
    lines = text.splitlines()
    start = next((i for i, ln in enumerate(lines) if ln.strip() and not ln.startswith("#")), None)
    if start is None:
        raise FormatError(path, None, "empty file: expected a header line")
    delim, decimal_comma = _sniff(path, lines[start])
    header = [h.strip() for h in next(csv.reader([lines[start]], delimiter=delim))]
    rows, numbers = [], []
    for i in range(start + 1, len(lines)):
        ln = lines[i]
        if not ln.strip() or ln.startswith("#"):
            continue
        cells = next(csv.reader([ln], delimiter=delim))
        if len(cells) != len(header):
            raise FormatError(path, i + 1, f"expected {len(header)} values for columns "
                                           f"{','.join(header)}, got {len(cells)}")
        row = []
        for name, cell in zip(header, cells):
            cell = cell.strip()
            if decimal_comma:
                cell = cell.replace(",", ".")
            if not cell and allow_empty:
                row.append(math.nan)
                continue
            try:
                v = float(cell)
            except ValueError:
                raise FormatError(path, i + 1, f"column {name!r}: expected a number, got "
                                               f"{cell!r}") from None
            if not math.isfinite(v):
                raise FormatError(path, i + 1, f"column {name!r}: expected a finite number, "
                                               f"got {cell!r}")
            row.append(v)
        numbers.append(row)
        rows.append(i + 1)
    if not numbers:
        raise FormatError(path, start + 1, "no data rows after the header")
    return header, np.asarray(numbers, dtype=np.float64), np.asarray(rows)


def _columns(path: Path, header: list[str], wanted: list[str]) -> list[int]:
    missing = [w for w in wanted if w not in header]
    if missing:
        raise FormatError(path, 1, f"missing column(s) {missing}; expected {wanted}, "
                                   f"found {header}")
    return [header.index(w) for w in wanted]


# ---------------------------------------------------------------------------------------------
# generic

def read_generic_csv(path: str | Path) -> list[Stream]:
    """Streams of a generic CSV (see the module docstring): one acc and one gyro per sensor;
    ``placement`` is the column prefix or ``None`` for the unprefixed single-sensor layout."""
    path = Path(path)
    header, data, lines = _read_table(path)
    if not header or header[0] != "time_s":
        raise FormatError(path, 1, f"expected first column 'time_s', found {header[:1]}")
    names = header[1:]
    if names == list(GENERIC_COLUMNS):
        prefixes: list[str | None] = [None]
    else:
        prefixes = []
        for n in names:
            p = n.rsplit(".", 1)[0] if "." in n else None
            if p is None or n.rsplit(".", 1)[1] not in GENERIC_COLUMNS:
                raise FormatError(path, 1, f"unexpected column {n!r}: expected "
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
    placement (``right_ankle.acc_x``). Refuses to replace a file unless ``overwrite``.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; pass overwrite=True (--force) to replace it")
    if rec.acc.shape[1] == 1:
        cols = list(GENERIC_COLUMNS)
    else:
        cols = [f"{p}.{c}" for p in rec.placements for c in GENERIC_COLUMNS]
    data = np.concatenate([rec.times[:, None], rec.channels()], axis=1)
    np.savetxt(path, data, delimiter=",", header=",".join(["time_s"] + cols), comments="",
               fmt=["%.6f"] + ["%.9g"] * (data.shape[1] - 1))
    return path


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
_UNITS = {"m/s^2": "m/s^2", "m/s²": "m/s^2", "g": "g", "rad/s": "rad/s", "deg/s": "deg/s",
          "°/s": "deg/s"}


def read_phyphox(path: str | Path) -> list[Stream]:
    """A phyphox CSV export: acceleration with g, gyroscope, or both in one table.

    Each signal takes the nearest ``Time (s)`` column to its left, so tables with one time
    column per sensor and tables with one shared time column both read.
    """
    path = Path(path)
    header, data, lines = _read_table(path, allow_empty=True)
    found: dict[str, dict[str, int]] = {}
    units: dict[str, str] = {}
    times: dict[str, int] = {}
    last_time = None
    for i, h in enumerate(header):
        if h.lower().startswith("time (s)"):
            last_time = i
            continue
        m = _PHYPHOX.match(h)
        if not m:
            continue
        kind = m.group(1).lower()
        if kind == "linear acceleration":
            raise FormatError(path, 1, f"column {h!r} is acceleration without gravity; export "
                                       "'Acceleration with g' instead")
        q = "acc" if kind == "acceleration" else "gyro"
        unit = _UNITS.get(m.group(3).strip())
        if unit is None:
            raise FormatError(path, 1, f"column {h!r}: unknown unit {m.group(3)!r}; expected "
                                       f"one of {sorted(set(_UNITS))}")
        if last_time is None:
            raise FormatError(path, 1, f"column {h!r} has no 'Time (s)' column before it")
        found.setdefault(q, {})[m.group(2).lower()] = i
        units[q], times[q] = unit, last_time
    if not found:
        raise FormatError(path, 1, "expected phyphox columns 'Time (s)', 'Acceleration x "
                                   f"(m/s^2)'... or 'Gyroscope x (rad/s)'..., found {header}")
    out = []
    for q, axes in found.items():
        if sorted(axes) != ["x", "y", "z"]:
            raise FormatError(path, 1, f"{q}: expected x, y and z columns, found {sorted(axes)}")
        cols = [times[q]] + [axes[a] for a in "xyz"]
        block = data[:, cols]
        ok = ~np.isnan(block).any(axis=1)
        partial = ~ok & ~np.isnan(block).all(axis=1)
        if partial.any():
            raise FormatError(path, int(lines[np.argmax(partial)]),
                              f"{q}: some of columns {[header[c] for c in cols]} are empty")
        out.append(Stream(path, q, block[ok, 0], block[ok, 1:], units[q], None, lines[ok]))
    return out


# ---------------------------------------------------------------------------------------------
# Sensor Logger

def _sensorlogger_file(path: Path, quantity: str, unit: str) -> Stream:
    header, data, lines = _read_table(path)
    idx = _columns(path, header, ["time", "x", "y", "z"])
    # ``time`` (Unix ns) rather than ``seconds_elapsed``: the same clock in every file, and
    # float64 keeps ~0.2 us at today's epoch, finer than any phone's timestamps.
    return Stream(path, quantity, data[:, idx[0]] * 1e-9, data[:, idx[1:]], unit, None, lines)


def _sensorlogger_platform(folder: Path) -> str:
    """``"ios"`` when Metadata.csv says so and units were not standardised, else android."""
    meta = folder / "Metadata.csv"
    if not meta.exists():
        return "android"
    with meta.open(encoding="utf-8-sig", newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        return "android"
    row = {k.strip().lower(): (v or "").strip().lower() for k, v in rows[0].items() if k}
    standard = any("standardis" in k or "standardiz" in k for k, v in row.items()
                   if v in ("true", "1", "yes"))
    return "ios" if row.get("platform", "") == "ios" and not standard else "android"


def read_sensor_logger(folder: str | Path, platform: str | None = None) -> list[Stream]:
    """A Sensor Logger export folder (unzipped): specific force with gravity and rotation rate.

    ``platform``: ``"android"`` or ``"ios"`` (iOS acceleration has the opposite sign); ``None``
    reads it from Metadata.csv (android when absent or when "Standardise Units & Frames" is on).
    """
    folder = Path(folder)
    platform = (platform or _sensorlogger_platform(folder)).lower()
    if platform not in ("android", "ios"):
        raise ValueError(f"platform must be 'android' or 'ios', got {platform!r}")
    gyro_path = folder / "Gyroscope.csv"
    if not gyro_path.exists():
        raise FormatError(folder, None, "expected Gyroscope.csv in the Sensor Logger export")
    total = folder / "TotalAcceleration.csv"
    if total.exists():
        acc = _sensorlogger_file(total, "acc", "m/s^2")
    else:
        user, grav = folder / "Accelerometer.csv", folder / "Gravity.csv"
        if not (user.exists() and grav.exists()):
            raise FormatError(folder, None, "expected TotalAcceleration.csv, or Accelerometer.csv "
                                            "(without gravity) together with Gravity.csv")
        acc = _sensorlogger_file(user, "acc", "m/s^2")
        g = _sensorlogger_file(grav, "acc", "m/s^2")
        order = np.argsort(g.times, kind="stable")
        for k in range(3):
            acc.values[:, k] += np.interp(acc.times, g.times[order], g.values[order, k])
    if platform == "ios":
        acc.values = -acc.values
    return [acc, _sensorlogger_file(gyro_path, "gyro", "rad/s")]


# ---------------------------------------------------------------------------------------------

def detect_format(path: str | Path) -> str:
    """Which reader fits ``path`` (a file, or a Sensor Logger folder)."""
    path = Path(path)
    if path.is_dir():
        if (path / "Gyroscope.csv").exists():
            return "sensorlogger"
        raise FormatError(path, None, "a folder must be a Sensor Logger export (Gyroscope.csv, "
                                      "TotalAcceleration.csv or Accelerometer.csv + Gravity.csv)")
    with path.open(encoding="utf-8-sig", errors="replace") as f:
        header = next((ln for ln in f if ln.strip() and not ln.startswith("#")), "")
    h = header.strip().lower()
    if h.startswith("time_s"):
        return "generic"
    if "attr_time" in h:
        return "realworld"
    if "time (s)" in h:
        return "phyphox"
    if h.startswith("time,seconds_elapsed"):
        return "sensorlogger"
    raise FormatError(path, 1, "unknown sensor log: expected a header starting 'time_s' "
                               "(generic), 'id,attr_time' (RealWorld), '\"Time (s)\"' (phyphox) "
                               f"or 'time,seconds_elapsed' (Sensor Logger), found {header[:80]!r}")
