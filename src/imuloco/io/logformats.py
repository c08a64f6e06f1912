"""The sensor-log formats imuloco reads: one table, one row a format (name, sniff, read).

``detect_format`` asks each row's ``sniff`` in turn; ``read_streams`` calls the row's ``read``.
A new format is one reader module and one :class:`LogFormat` row in :data:`LOG_FORMATS`: the
CLI's ``--format`` choices, ``imuloco.sensors.reallog.read_log`` and the fuzzer read the table.
Export folders and zips (Sensor Logger, phyphox) name their own kind
(:meth:`imuloco.io.sensorlog.Export.kind`); a single file is sniffed from its first header line.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from imuloco.errors import FormatError, InputError, UnknownNameError, excerpt
from imuloco.io.sensorlog import (
    _SENSOR_LOGGER_HEADER,
    Export,
    Stream,
    _sniff,
    _split,
    _text_lines,
    is_export,
    read_generic_csv,
    read_phyphox,
    read_phyphox_export,
    read_realworld,
    read_sensor_logger,
)
from imuloco.io.xsens import is_xsens, read_xsens
from imuloco.limits import FORMATS


@dataclass(frozen=True)
class LogFormat:
    """One sensor-log format.

    name : what ``--format`` calls it.
    sniff : (path, its first header line, lower case) -> whether a single file is this format.
    read : (path, a second file or None, the phone's platform or None, whether ``path`` is an
        export folder or zip) -> the streams the file holds.
    second_file : whether the format may come as two files (accelerometer, gyroscope); a
        second file beside a format that holds both signals in one is refused.
    """

    name: str
    sniff: Callable[[Path, str], bool]
    read: Callable[[Path, Path | None, str | None, bool], list[Stream]]
    second_file: bool = False


def _read_phyphox(path: Path, second: Path | None, platform: str | None,
                  export: bool) -> list[Stream]:
    streams = read_phyphox_export(path) if export else read_phyphox(path)
    if second is not None:  # a second export (zip or folder) or table
        streams += read_phyphox_export(second) if is_export(second) else read_phyphox(second)
    return streams


def _read_xsens(path: Path, second: Path | None, platform: str | None,
                export: bool) -> list[Stream]:
    if export:
        raise FormatError(path, None, "an Xsens export is one text file per sensor: give the file")
    return read_xsens(path)


LOG_FORMATS: tuple[LogFormat, ...] = (
    LogFormat("generic", lambda path, h: h.startswith("time_s"),
              lambda path, second, platform, export: read_generic_csv(path)),
    LogFormat("realworld", lambda path, h: "attr_time" in h,
              lambda path, second, platform, export: read_realworld(
                  *realworld_pair(path, second)), second_file=True),
    LogFormat("phyphox", lambda path, h: "time (s)" in h, _read_phyphox, second_file=True),
    LogFormat("sensorlogger", lambda path, h: h.startswith(_SENSOR_LOGGER_HEADER),
              lambda path, second, platform, export: read_sensor_logger(
                  path if export else path.parent, platform)),
    LogFormat("xsens", lambda path, h: is_xsens(path), _read_xsens),
)
BY_NAME = {f.name: f for f in LOG_FORMATS}
if tuple(BY_NAME) != FORMATS:  # the names the CLI shows, from the import-light module
    raise RuntimeError(f"imuloco.limits.FORMATS {FORMATS} must name the rows of LOG_FORMATS "
                       f"in order, {tuple(BY_NAME)}")


def log_format(name: str) -> LogFormat:
    """The row named ``name``; :class:`UnknownNameError` listing the names otherwise."""
    if name not in BY_NAME:
        raise UnknownNameError(f"unknown log format {name!r}; expected one of "
                               f"{['auto', *FORMATS]}")
    return BY_NAME[name]


def detect_format(path: str | Path) -> str:
    """Which reader fits ``path`` (a file, an export folder or an export zip)."""
    path = Path(path)
    if is_export(path):
        with Export(path) as ex:
            kind = ex.kind()
        if kind is None:
            raise FormatError(path, None, "expected a Sensor Logger export (Gyroscope.csv with "
                                          "TotalAcceleration.csv, or Accelerometer.csv + "
                                          "Gravity.csv) or a phyphox export (tables with "
                                          f"'Time (s)' columns); found {ex.names()[:10]}")
        return kind
    with open(path, "rb") as f:
        header = next((ln for _, ln in _text_lines(path, f)
                       if ln.strip() and not ln.startswith("#")), "")
    h = header.strip().lower()
    for fmt in LOG_FORMATS:
        if fmt.sniff(path, h):
            return fmt.name
    raise FormatError(path, 1, "unknown sensor log: expected a header starting 'time_s' "
                               "(generic), 'id,attr_time' (RealWorld), '\"Time (s)\"' (phyphox) "
                               "or 'time,seconds_elapsed' (Sensor Logger), or an Xsens export's "
                               "('// Update Rate: ...' lines, then 'PacketCounter ... Acc_X "
                               f"... Gyr_X ...'), found first column "
                               f"{excerpt(_split(path, 1, header, _sniff(header)[0])[0])}; another "
                               "CSV: name its columns with --columns time=COLUMN,acc_x=COLUMN,...")


def read_streams(path: Path, fmt: str = "auto", second: Path | None = None,
                 platform: str | None = None, columns: dict[str, str] | None = None
                 ) -> tuple[str, list[Stream]]:
    """The format of ``path`` (detected when ``"auto"``) and the streams its reader found;
    ``second``: a second file (a RealWorld gyroscope, a phyphox gyroscope table or export);
    ``columns``: a CSV's own names of the generic columns (:func:`parse_columns`): read as
    generic."""
    if columns:
        if fmt not in ("auto", "generic"):
            raise InputError(f"a column mapping is for generic CSV logs, not {fmt}")
        if second is not None:
            raise FormatError(second, None, "a second file, but a generic log holds both "
                                            f"signals in {path.name}: give one file")
        return "generic", read_generic_csv(path, columns)
    row = log_format(detect_format(path) if fmt == "auto" else fmt)
    if second is not None and not row.second_file:
        raise FormatError(second, None, f"a second file, but a {row.name} log holds both "
                                        f"signals in {path.name}: give one file (many walkers: "
                                        "imuloco batch)")
    return row.name, row.read(path, second, platform, is_export(path))


# ---- RealWorld's two files -----------------------------------------------------------------
RW_ACC, RW_GYRO = ("acc_",), ("gyroscope_", "gyr_")  # RealWorld file names, any case


def _rw_kind(path: Path) -> tuple[str | None, str]:
    """``("acc" | "gyro" | None, the name after its prefix)`` of a RealWorld file."""
    low = path.name.lower()
    for kind, prefixes in (("acc", RW_ACC), ("gyro", RW_GYRO)):
        for p in prefixes:
            if low.startswith(p):
                return kind, path.name[len(p):]
    return None, path.name


def realworld_accelerometer(path: str | Path) -> Path | None:
    """For a RealWorld gyroscope file (``gyroscope_X.csv``, ``gyr_X.csv``), the
    ``acc_X.csv`` beside it that reads the pair; None for any other file."""
    path = Path(path)
    kind, rest = _rw_kind(path)
    return path.with_name(RW_ACC[0] + rest) if kind == "gyro" else None


def realworld_pair(path: Path, gyro_path: Path | None) -> tuple[Path, Path]:
    """The (accelerometer, gyroscope) files of a RealWorld log: ``acc_X.csv`` finds
    ``gyroscope_X.csv`` beside it; a pair whose names say it was given gyroscope first is
    turned round. A gyroscope file alone is refused, naming its accelerometer file (which
    finds it: a folder's files given one by one, as ``batch --glob`` does, are one walker)."""
    kind, rest = _rw_kind(path)
    if gyro_path is not None:
        return (gyro_path, path) if (kind, _rw_kind(gyro_path)[0]) == ("gyro", "acc") else (
            path, gyro_path)
    if kind != "acc":
        raise FormatError(path, None, "a RealWorld log comes as two files, acc_NAME.csv and "
                                      "gyroscope_NAME.csv: give the acc_ file (it finds the "
                                      "other) or both" + (f" (acc_{rest})" if kind else ""))
    names = [p + rest for p in RW_GYRO]
    found = sorted(f for f in path.parent.iterdir()
                   if f.name.lower() in {n.lower() for n in names} and f.is_file())
    if not found:
        raise FormatError(path, None, f"a RealWorld log comes as two files: no "
                                      f"{' or '.join(names)} beside it (give both files)")
    return path, found[0]
