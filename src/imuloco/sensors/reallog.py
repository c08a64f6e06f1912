"""Real sensor logs: from a phone's CSV export to a :class:`Recording` at the model's rate.

The steps, each reported in a :class:`LogReport`:

1. read the file(s) with :mod:`imuloco.io.sensorlog` (generic, RealWorld, phyphox, Sensor Logger);
2. per signal, sort the timestamps (stable) and drop repeated ones, keeping the first sample;
3. detect the units where the format leaves them open (explicit ``acc_unit``/``gyro_unit``
   override): the accelerometer's median magnitude is ~1 in g and ~9.8 in m/s^2 (gravity
   dominates it during walking too); the gyroscope's from its magnitude distribution
   (:func:`detect_gyro_unit`). A prediction test (integrate the gyroscope, turn the gravity
   direction with it) was tried and dropped: on a shank the low-passed specific force is
   dominated by centripetal acceleration during the swing and does not follow gravity;
4. align the accelerometer and gyroscope by time (the gyroscope is interpolated linearly at the
   accelerometer's timestamps over the interval both cover) and start the clock at 0;
5. resample to ``rate`` with linear interpolation and a 1-D Gaussian filter, as Eom et al. 2014
   do (sec. 4.1; they give no width, we default to sigma = 10 ms: -3 dB at ~13 Hz, above the
   gait's content, below the jitter of phone timestamps), via
   :func:`imuloco.sensors.resample.resample`.

Gaps longer than ``max_gap`` in either signal are returned and logged; with ``on_gap="raise"``
they are an error instead of being bridged by the interpolation.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from imuloco.core.recording import Recording
from imuloco.errors import FormatError
from imuloco.io.sensorlog import (
    Stream,
    detect_format,
    read_generic_csv,
    read_phyphox,
    read_realworld,
    read_sensor_logger,
)
from imuloco.ops.filters import resample_linear
from imuloco.sensors.resample import Gap, find_gaps, resample

log = logging.getLogger(__name__)

STANDARD_GRAVITY = 9.80665  # m/s^2 per g
ACC_UNITS = {"m/s^2": 1.0, "g": STANDARD_GRAVITY}
GYRO_UNITS = {"rad/s": 1.0, "deg/s": np.pi / 180.0}
_GYRO_DEG_MAGNITUDE = 35.0  # rad/s: 2000 deg/s is 34.9 rad/s, the largest phone range


@dataclass
class LogReport:
    """What importing a log found and did.

    Attributes
    ----------
    format : reader used (see :data:`imuloco.io.sensorlog.FORMATS`).
    files : the files read.
    samples : samples per signal after cleaning, ``{"acc": n, "gyro": m}`` (summed over sensors).
    unsorted : samples whose timestamp was earlier than the one before (per signal).
    duplicates : samples dropped for repeating a timestamp (per signal).
    acc_unit, gyro_unit : units of the file; ``*_detected`` tells whether they were detected.
    source_rate : median sampling rate of the accelerometer, Hz.
    start_time : the file's clock at the recording's time 0, seconds (Unix time for phones).
    duration : seconds covered by both signals.
    gaps : stretches longer than ``max_gap`` without samples in either signal, in the
        recording's time (seconds from ``start_time``).
    """

    format: str
    files: list[str]
    samples: dict[str, int] = field(default_factory=dict)
    unsorted: dict[str, int] = field(default_factory=dict)
    duplicates: dict[str, int] = field(default_factory=dict)
    acc_unit: str = "m/s^2"
    gyro_unit: str = "rad/s"
    acc_unit_detected: bool = False
    gyro_unit_detected: bool = False
    source_rate: float = float("nan")
    start_time: float = 0.0
    duration: float = 0.0
    gaps: list[Gap] = field(default_factory=list)


def clean_times(times: np.ndarray, values: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, int, int]:
    """Sort samples by time (stable) and keep the first of repeated timestamps.

    Parameters
    ----------
    times : ndarray, shape (N,), seconds.
    values : ndarray, shape (N, ...).

    Returns
    -------
    times (M,), values (M, ...), number of samples that were out of order, number dropped as
    duplicates.
    """
    unsorted = int(np.count_nonzero(np.diff(times) < 0))
    order = np.argsort(times, kind="stable")
    times, values = times[order], values[order]
    keep = np.concatenate([[True], np.diff(times) > 0])
    return times[keep], values[keep], unsorted, int(np.count_nonzero(~keep))


def detect_acc_unit(acc: np.ndarray) -> str:
    """``"g"`` or ``"m/s^2"`` from the median magnitude of specific force (N, 3) that includes
    gravity: below 3.13 (the geometric mean of 1 and 9.81) is g."""
    med = float(np.median(np.linalg.norm(acc, axis=-1)))
    return "g" if med < np.sqrt(STANDARD_GRAVITY) else "m/s^2"


def detect_gyro_unit(gyro: np.ndarray) -> str:
    """``"rad/s"`` or ``"deg/s"`` from the magnitude distribution of angular velocity (N, 3).

    Beyond 35 units at the 99th percentile it is deg/s: above any phone's +-2000 deg/s range
    expressed in rad/s. Between 1.5 and 35 it is rad/s: a leg or trunk moving at all turns at
    several rad/s (walking shank: 4-7 rad/s), and the same rates in deg/s would be a body
    nearly at rest. Below 1.5 the phone rests: the median magnitude is its bias and noise,
    ~0.2-1 deg/s against ~0.005-0.02 rad/s, split at 0.05 (logged: pass ``gyro_unit=``).
    """
    mag = np.linalg.norm(gyro, axis=-1)
    p99 = np.percentile(mag, 99)
    if p99 > _GYRO_DEG_MAGNITUDE:
        return "deg/s"
    if p99 >= 1.5:
        return "rad/s"
    unit = "deg/s" if np.median(mag) > 0.05 else "rad/s"
    log.warning("gyroscope unit: the recording hardly moves; assuming %s from its noise floor "
                "(pass gyro_unit= to override)", unit)
    return unit


def _merge_gaps(gaps: list[Gap]) -> list[Gap]:
    out: list[Gap] = []
    for g in sorted(gaps, key=lambda g: g.start):
        if out and g.start <= out[-1].stop:
            out[-1] = Gap(out[-1].start, max(out[-1].stop, g.stop))
        else:
            out.append(g)
    return out


def _read_streams(path: Path | Sequence[Path], fmt: str, gyro_path: Path | None,
                  platform: str | None) -> tuple[str, list[Stream]]:
    if isinstance(path, (list, tuple)):
        path, gyro_path = Path(path[0]), Path(path[1])
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file or folder")
    fmt = detect_format(path) if fmt == "auto" else fmt
    if fmt == "generic":
        return fmt, read_generic_csv(path)
    if fmt == "phyphox":
        streams = read_phyphox(path)
        if gyro_path is not None:
            streams += read_phyphox(gyro_path)
        return fmt, streams
    if fmt == "sensorlogger":
        return fmt, read_sensor_logger(path if path.is_dir() else path.parent, platform)
    if fmt == "realworld":
        if gyro_path is None:
            name = path.name
            for a, b in (("acc_", "gyroscope_"), ("acc_", "Gyroscope_"), ("acc_", "gyr_")):
                cand = path.with_name(b + name[len(a):]) if name.lower().startswith(a) else None
                if cand is not None and cand.exists():
                    gyro_path = cand
                    break
            else:
                raise FormatError(path, None, "RealWorld logs come as an acc_*.csv and a "
                                              "gyroscope_*.csv file: pass gyro_path=")
        return fmt, read_realworld(path, gyro_path)
    raise ValueError(f"unknown log format {fmt!r}; expected 'auto', 'generic', 'realworld', "
                     "'phyphox' or 'sensorlogger'")


def read_log(
    path: str | Path | Sequence[str | Path],
    placement: str = "right_ankle",
    fmt: str = "auto",
    *,
    gyro_path: str | Path | None = None,
    acc_unit: str = "auto",
    gyro_unit: str = "auto",
    rate: float | None = 100.0,
    sigma_s: float = 0.01,
    max_gap: float = 0.2,
    on_gap: str = "warn",
    platform: str | None = None,
) -> tuple[Recording, LogReport]:
    """Import a phone's sensor log as a :class:`Recording` in m/s^2 and rad/s.

    Parameters
    ----------
    path : a log file, a Sensor Logger folder, or an (accelerometer, gyroscope) file pair.
    placement : placement name of the sensor when the file names none (generic multi-sensor
        files name theirs).
    fmt : ``"auto"`` (from the header) or one of :data:`imuloco.io.sensorlog.FORMATS`.
    gyro_path : the gyroscope file of formats that split the signals (RealWorld, phyphox).
    acc_unit : ``"auto"``, ``"m/s^2"`` or ``"g"``; gyro_unit : ``"auto"``, ``"rad/s"`` or
        ``"deg/s"``. ``"auto"`` takes the unit a format declares and detects it otherwise.
    rate : model rate in Hz to resample to; ``None`` keeps the aligned irregular samples.
    sigma_s : width of the Gaussian smoothing, seconds (added to resampling's anti-aliasing).
    max_gap : seconds without samples above which a gap is reported.
    on_gap : ``"warn"`` (report, log and interpolate across) or ``"raise"``.
    platform : Sensor Logger only, ``"android"``/``"ios"`` (default: from Metadata.csv).

    Returns
    -------
    The recording (times from 0 s) and a :class:`LogReport`.
    """
    if acc_unit not in ("auto", *ACC_UNITS):
        raise ValueError(f"acc_unit must be 'auto' or one of {list(ACC_UNITS)}, got {acc_unit!r}")
    if gyro_unit not in ("auto", *GYRO_UNITS):
        raise ValueError(f"gyro_unit must be 'auto' or one of {list(GYRO_UNITS)}, got "
                         f"{gyro_unit!r}")
    if on_gap not in ("warn", "raise"):
        raise ValueError(f"on_gap must be 'warn' or 'raise', got {on_gap!r}")
    fmt, streams = _read_streams(path, fmt, None if gyro_path is None else Path(gyro_path),
                                 platform)
    report = LogReport(fmt, sorted({str(s.path) for s in streams}))
    # group per sensor: placement named in the file, or the caller's
    sensors: dict[str, dict[str, Stream]] = {}
    for s in streams:
        sensors.setdefault(s.placement or placement, {})[s.quantity] = s
    for name, pair in sensors.items():
        for q in ("acc", "gyro"):
            if q not in pair:
                raise FormatError(report.files[0], None, f"sensor {name!r}: no "
                                  f"{'accelerometer' if q == 'acc' else 'gyroscope'} signal found")
    # clean
    cleaned: dict[str, dict[str, tuple[np.ndarray, np.ndarray]]] = {}
    for name, pair in sensors.items():
        cleaned[name] = {}
        for q, s in pair.items():
            t, v, n_uns, n_dup = clean_times(s.times, s.values)
            if len(t) < 2:
                raise FormatError(s.path, None, f"{q}: expected at least 2 distinct timestamps")
            cleaned[name][q] = (t, v)
            report.unsorted[q] = report.unsorted.get(q, 0) + n_uns
            report.duplicates[q] = report.duplicates.get(q, 0) + n_dup
            report.samples[q] = report.samples.get(q, 0) + len(t)
            if n_uns or n_dup:
                log.info("%s (%s): %d samples out of order sorted, %d repeated timestamps "
                         "dropped", s.path, q, n_uns, n_dup)
    # common time interval and reference timestamps (first sensor's accelerometer)
    t0 = max(t[0] for pair in cleaned.values() for t, _ in pair.values())
    t1 = min(t[-1] for pair in cleaned.values() for t, _ in pair.values())
    if t1 <= t0:
        raise FormatError(report.files[0], None, "the accelerometer and gyroscope recordings "
                                                 "do not overlap in time")
    ref_t = next(iter(cleaned.values()))["acc"][0]
    times = ref_t[(ref_t >= t0) & (ref_t <= t1)]
    gaps = []
    for pair in cleaned.values():
        for t, _ in pair.values():
            inside = t[(t >= t0) & (t <= t1)]
            gaps += find_gaps(np.concatenate([[t0], inside, [t1]]), max_gap)
    report.gaps = [Gap(float(g.start - t0), float(g.stop - t0)) for g in _merge_gaps(gaps)]
    report.start_time, report.duration = float(t0), float(t1 - t0)
    report.source_rate = float(1.0 / np.median(np.diff(times)))
    names = list(cleaned)
    acc = np.stack([resample_linear(*cleaned[n]["acc"], times) for n in names], axis=1)
    gyro = np.stack([resample_linear(*cleaned[n]["gyro"], times) for n in names], axis=1)
    # units
    declared = {q: {sensors[n][q].unit for n in names} - {None} for q in ("acc", "gyro")}
    if acc_unit == "auto":
        if declared["acc"]:
            acc_unit = declared["acc"].pop()
        else:
            acc_unit = detect_acc_unit(acc.reshape(-1, 3))
            report.acc_unit_detected = True
    acc = acc * ACC_UNITS[acc_unit]
    if gyro_unit == "auto":
        if declared["gyro"]:
            gyro_unit = declared["gyro"].pop()
        else:
            votes = [detect_gyro_unit(gyro[:, k]) for k in range(len(names))]
            gyro_unit = max(set(votes), key=votes.count)
            report.gyro_unit_detected = True
    gyro = gyro * GYRO_UNITS[gyro_unit]
    report.acc_unit, report.gyro_unit = acc_unit, gyro_unit
    for g in report.gaps:
        log.warning("%s: no samples from %.3f s to %.3f s (%.3f s gap)", report.files[0],
                    g.start, g.stop, g.stop - g.start)
    if report.gaps and on_gap == "raise":
        worst = max(report.gaps, key=lambda g: g.stop - g.start)
        raise ValueError(f"{report.files[0]}: {len(report.gaps)} gap(s) longer than {max_gap} s, "
                         f"the longest {worst.stop - worst.start:.3f} s from {worst.start:.3f} s")
    rec = Recording(times - t0, acc, gyro, names)
    if rate is not None:
        rec, _ = resample(rec, rate, sigma_s=sigma_s, max_gap=np.inf)  # gaps reported above
    return rec, report
