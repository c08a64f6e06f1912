"""Real sensor logs: from a phone's CSV export to a :class:`Recording` at the model's rate.

The steps, each reported in a :class:`LogReport`:

1. read the file(s) with :mod:`imuloco.io.sensorlog` (generic, RealWorld, phyphox, Sensor Logger,
   Xsens text exports);
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
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from imuloco.core.recording import Recording
from imuloco.errors import FormatError, InputError, MissingInputError, UnknownNameError
from imuloco.io.logformats import (  # noqa: F401  (realworld_accelerometer: batch's name for it)
    FORMATS,
    read_streams,
    realworld_accelerometer,
)
from imuloco.io.sensorlog import PLATFORMS, Stream
from imuloco.limits import MAX_RATE, MIN_RATE
from imuloco.ops.filters import resample_linear
from imuloco.sensors.resample import Gap, find_gaps, resample

log = logging.getLogger(__name__)

STANDARD_GRAVITY = 9.80665  # m/s^2 per g
ACC_UNITS = {"m/s^2": 1.0, "g": STANDARD_GRAVITY}
GYRO_UNITS = {"rad/s": 1.0, "deg/s": np.pi / 180.0}
_GYRO_DEG_MAGNITUDE = 35.0  # rad/s: 2000 deg/s is 34.9 rad/s, the largest phone range


@dataclass
class SensorSource:
    """Where one sensor of a recording came from and how its clock was put on the
    recording's (the report's ``sensors``).

    placement : the sensor's placement; file : the file (or export member) it was read from.
    offset_s : seconds added to the file's clock to put it on the first sensor's.
    aligned_by : ``"timestamps"`` (one clock: a file's columns, an export's files, or Unix
        times of devices synchronised to it) or ``"xcorr"`` (a stomp or clap at the start,
        :func:`imuloco.sensors.multi.align_by_xcorr`).
    correlation : the normalised cross-correlation at the offset found (``"xcorr"`` only).
    used : whether the model read this sensor (set by the pipeline; ``None``: not yet known).
    """

    placement: str
    file: str
    offset_s: float = 0.0
    aligned_by: str = "timestamps"
    correlation: float | None = None
    used: bool | None = None

    def to_json(self) -> dict[str, Any]:
        return {"placement": self.placement, "file": self.file,
                "offset_s": round(self.offset_s, 4), "aligned_by": self.aligned_by,
                "correlation": None if self.correlation is None else round(self.correlation, 3),
                "used": self.used}


@dataclass
class LogReport:
    """What importing a log found and did.

    Attributes
    ----------
    format : reader used (see :data:`imuloco.io.logformats.FORMATS`).
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
    time_unit : the unit the timestamps turned out to have (``"ms"`` in a ``time_s`` column
        that holds milliseconds, see :func:`_time_scale`).
    platform : Sensor Logger: the platform applied and how it was found.
    sensors : per sensor, its file and clock alignment (:class:`SensorSource`).
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
    time_unit: str = "s"
    platform: str | None = None
    sensors: list[SensorSource] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        """The ``recording`` part of a reconstruction's report (keys are a contract)."""
        return {"files": self.files, "format": self.format,
                "duration_s": round(self.duration, 3),
                "source_rate_hz": round(self.source_rate, 2), "samples": self.samples,
                "unsorted": self.unsorted, "duplicates": self.duplicates,
                "acc_unit": self.acc_unit, "gyro_unit": self.gyro_unit,
                "gaps": [[round(g.start, 3), round(g.stop, 3)] for g in self.gaps],
                "time_unit": self.time_unit, "platform": self.platform}


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


# plausibility ranges of an imported log (bad files are refused with the line that breaks them)
# a median rate this close to a bound is on it: the median step of a log with timestamp jitter
# estimates its rate only so closely (phone jitter: up to 1.2 % off at 5 Hz over 1 s, 0.3 % at
# 10 kHz, so such a log at a bound was refused by chance), as does the float rounding of the
# timestamps' differences (10 ppm covers Unix seconds)
RATE_RTOL = 0.02
MIN_DURATION = 1.0  # seconds both signals cover: shorter is not a movement to reconstruct
MAX_DURATION = 48 * 3600.0  # seconds: longer logs are refused rather than resampled
MAX_SPAN_RATIO = 10.0  # the log may span at most 10x (+ 60 s) the time its samples cover
MAX_ABS_TIME = 1e13  # seconds: timestamps beyond are garbage (Unix time is ~1.7e9)
MAX_VALUE = {"acc": 1e4, "gyro": 1e5}  # per axis, in any unit: 1,000 g; 10^5 deg/s
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
FORMAT_NAMES = ("auto", *FORMATS)


def _read_streams(path: Path | Sequence[Path], fmt: str, gyro_path: Path | None,
                  platform: str | None, columns: dict[str, str] | None = None
                  ) -> tuple[str, list[Stream]]:
    """Step 1: the format (detected when ``"auto"``) and the streams the reader found
    (:func:`imuloco.io.logformats.read_streams`)."""
    if isinstance(path, (list, tuple)):
        if len(path) != 2:
            raise InputError(f"expected one log or an (accelerometer, gyroscope) pair of files, "
                             f"got {len(path)} files (many walkers: imuloco batch)")
        path, gyro_path = Path(path[0]), Path(path[1])
    path = Path(path)
    if not path.exists():
        raise MissingInputError(f"{path}: no such file or folder")
    return read_streams(path, fmt, gyro_path, platform, columns)


def recording_name(path: str | Path) -> str:
    """A recording's own name: a file's stem, an export folder's whole name (``alice.day1``;
    ``.`` is named after the folder it stands for)."""
    full = Path(os.path.normpath(Path(path).absolute()))
    return full.name if full.is_dir() else full.stem


def _sensors(streams: list[Stream], placement: str) -> dict[str, dict[str, Stream]]:
    """Streams grouped per sensor (the placement the file names, or ``placement``), each with
    an accelerometer and a gyroscope."""
    sensors: dict[str, dict[str, Stream]] = {}
    named = {s.placement for s in streams} - {None}
    if placement in named and any(s.placement is None for s in streams):
        raise FormatError(streams[0].path, None, f"the log's own sensor is read at {placement!r}"
                          f", where the export's other sensor ({named_file(streams, placement)})"
                          " is too: give the phone's placement with --placement")
    for s in streams:
        sensors.setdefault(s.placement or placement, {})[s.quantity] = s
    for name, pair in sensors.items():
        for q in ("acc", "gyro"):
            if q not in pair:
                raise FormatError(streams[0].path, None, f"sensor {name!r}: no "
                                  f"{'accelerometer' if q == 'acc' else 'gyroscope'} signal found")
    return sensors


def named_file(streams: list[Stream], placement: str) -> str:
    """The file of the stream at ``placement`` (for messages)."""
    return next(str(s.path) for s in streams if s.placement == placement)


MIN_OVERLAP = 0.8  # share of the shortest sensor's span the sensors must record together


def check_overlap(spans: dict[str, tuple[float, float]], files: dict[str, str]) -> None:
    """Refuse sensors (placement -> (start, stop) seconds on one clock) that record together
    less than :data:`MIN_OVERLAP` of the shortest one's span: a reconstruction from several
    sensors reads them all at every frame, so the rest would be lost or guessed."""
    if len(spans) < 2:
        return
    start = max(a for a, _ in spans.values())
    stop = min(b for _, b in spans.values())
    shortest = min(spans, key=lambda n: spans[n][1] - spans[n][0])
    length = spans[shortest][1] - spans[shortest][0]
    together = max(stop - start, 0.0)
    if together < MIN_OVERLAP * length:
        late = max(spans, key=lambda n: spans[n][0])
        early = min(spans, key=lambda n: spans[n][1])
        raise FormatError(files[shortest], None, f"the sensors record together {together:.3g} s, "
                          f"{100 * together / max(length, 1e-9):.0f} % of the shortest one's "
                          f"{length:.3g} s ({shortest}); expected at least "
                          f"{100 * MIN_OVERLAP:.0f} %: {late} ({files[late]}) starts at "
                          f"{spans[late][0] - min(a for a, _ in spans.values()):.3g} s, "
                          f"{early} ({files[early]}) stops at "
                          f"{spans[early][1] - min(a for a, _ in spans.values()):.3g} s")


def _check_values(s: Stream) -> None:
    """Values within :data:`MAX_VALUE` and timestamps within :data:`MAX_ABS_TIME`, else the
    first offending line is named."""
    for what, bad, limit in (
            ("value", np.abs(s.values).max(axis=1) > MAX_VALUE[s.quantity], MAX_VALUE[s.quantity]),
            ("timestamp", np.abs(s.times) > MAX_ABS_TIME, MAX_ABS_TIME)):
        if bad.any():
            k = int(np.argmax(bad))
            raise FormatError(s.path, _line(s, k), f"{s.quantity}: {what} beyond +-{limit:g} "
                                                   "is not a sensor reading")


def _line(s: Stream, k: int) -> int | None:
    return None if s.lines is None else int(s.lines[k])


def _time_scale(s: Stream, times: np.ndarray) -> float:
    """Seconds per unit of the stream's timestamps: 1 when its median rate is plausible, else
    the unit (ms, us, ns) that makes it so (a ``time_s`` column holding milliseconds), warned.
    A unit is only taken if the signal then lasts :data:`MIN_DURATION`: a log of a few Hz in
    seconds is refused for its rate, not read as milliseconds lasting a few hundredths of a
    second; one too short to tell (a few samples) is refused with both readings.

    ``times`` : ndarray, shape (N,), sorted distinct timestamps of ``s`` as read."""
    med = float(np.median(np.diff(times)))
    span = float(times[-1] - times[0])
    lo, hi = MIN_RATE * (1 - RATE_RTOL), MAX_RATE * (1 + RATE_RTOL)
    rated = [(u, k) for u, k in TIME_UNITS.items() if lo <= 1.0 / (med * k) <= hi]
    lasting = [(u, k) for u, k in rated if span * k >= MIN_DURATION]
    if lasting:
        unit, scale = lasting[0]
        if unit != "s":
            log.warning("%s (%s): the timestamps step by %.4g per sample, %.3g Hz in seconds; "
                        "read as %s (%.3g Hz)", s.path, s.quantity, med, 1.0 / med, unit,
                        1.0 / (med * scale))
        return scale
    if span >= MIN_DURATION and 1.0 / med < lo:  # in seconds, long enough but too slow
        other = "".join(f"; read as {u} ({1.0 / (med * k):.3g} Hz) it would last only "
                        f"{span * k:.3g} s" for u, k in rated[:1])
        raise FormatError(s.path, None, f"{s.quantity}: the timestamps step by a median "
                                        f"{med:.3g} s per sample, a rate of {1.0 / med:.3g} Hz: "
                                        f"too low for gait, expected at least {MIN_RATE:g} Hz"
                                        + other)
    if rated and rated[0][0] == "s":
        return 1.0  # a rate in seconds, too short: refused for its length
    if rated:  # too slow in seconds, too short in every unit with a rate: both readings said
        unit, scale = rated[0]
        raise FormatError(s.path, None, f"{s.quantity}: {len(times)} timestamps a median {med:.3g} "
                                        f"apart: in seconds a rate of {1.0 / med:.3g} Hz "
                                        f"(expected at least {MIN_RATE:g} Hz); read as {unit}, "
                                        f"{1.0 / (med * scale):.3g} Hz for only "
                                        f"{span * scale:.3g} s (expected at least "
                                        f"{MIN_DURATION:g} s)")
    raise FormatError(s.path, None, f"{s.quantity}: the timestamps step by a median {med:.3g} "
                                    f"per sample: in s, ms, us or ns that is no sampling rate "
                                    f"between {MIN_RATE:g} and {MAX_RATE:g} Hz")


def _clean(sensors: dict[str, dict[str, Stream]], report: LogReport
           ) -> dict[str, dict[str, tuple[np.ndarray, np.ndarray]]]:
    """Step 2: per signal, plausible values, sorted distinct timestamps in seconds."""
    cleaned: dict[str, dict[str, tuple[np.ndarray, np.ndarray]]] = {}
    for name, pair in sensors.items():
        cleaned[name] = {}
        for q, s in pair.items():
            _check_values(s)
            t, v, n_uns, n_dup = clean_times(s.times, s.values)
            if len(t) < 3:
                raise FormatError(s.path, None, f"{q}: expected at least 3 distinct timestamps, "
                                                f"found {len(t)}")
            scale = _time_scale(s, t)
            _check_span(s, t, scale)
            if scale != 1.0:
                report.time_unit = next(u for u, k in TIME_UNITS.items() if k == scale)
            cleaned[name][q] = (t * scale, v)
            report.unsorted[q] = report.unsorted.get(q, 0) + n_uns
            report.duplicates[q] = report.duplicates.get(q, 0) + n_dup
            report.samples[q] = report.samples.get(q, 0) + len(t)
            if n_uns or n_dup:
                log.info("%s (%s): %d samples out of order sorted, %d repeated timestamps "
                         "dropped", s.path, q, n_uns, n_dup)
    return cleaned


def _check_span(s: Stream, t: np.ndarray, scale: float) -> None:
    """A signal's timestamps ``t`` (sorted, distinct, in the file's unit; seconds = ``t *
    scale``) must span at most :data:`MAX_DURATION` and not much more than its samples cover:
    a timestamp jumping by days would otherwise resample to billions of samples."""
    d = np.diff(t) * scale
    covered = len(t) * float(np.median(d))
    span = float(t[-1] - t[0]) * scale
    if span > min(MAX_SPAN_RATIO * covered + 60.0, MAX_DURATION):
        k = int(np.argmax(d)) + 1
        raise FormatError(s.path, _line(s, int(np.flatnonzero(s.times == t[k])[0])),
                          f"{s.quantity}: the log spans {span:.4g} s but its {len(t)} samples "
                          f"cover ~{covered:.4g} s (at most {MAX_DURATION / 3600:g} h are read); "
                          f"the timestamp here jumps by {d.max():.4g} s")


def _gaps(cleaned: dict[str, dict[str, tuple[np.ndarray, np.ndarray]]], t0: float, t1: float,
          max_gap: float) -> list[Gap]:
    """Stretches longer than ``max_gap`` without samples in any signal, seconds from ``t0``."""
    gaps = []
    for pair in cleaned.values():
        for t, _ in pair.values():
            inside = t[(t >= t0) & (t <= t1)]
            gaps += find_gaps(np.concatenate([[t0], inside, [t1]]), max_gap)
    return [Gap(float(g.start - t0), float(g.stop - t0)) for g in _merge_gaps(gaps)]


def _units(signals: np.ndarray, quantity: str, unit: str, declared: set[str]
           ) -> tuple[np.ndarray, str, bool]:
    """Step 3: ``signals`` (T, S, 3) in SI units, the unit found and whether it was detected."""
    detected = False
    if unit == "auto":
        if declared:
            unit = declared.pop()
        elif quantity == "acc":
            unit, detected = detect_acc_unit(signals.reshape(-1, 3)), True
        else:
            votes = [detect_gyro_unit(signals[:, k]) for k in range(signals.shape[1])]
            unit, detected = max(set(votes), key=votes.count), True
    return signals * (ACC_UNITS if quantity == "acc" else GYRO_UNITS)[unit], unit, detected


@dataclass(frozen=True)
class LogOptions:
    """How :func:`read_log` imports a log (its keyword arguments, documented there)."""

    placement: str = "right_ankle"
    fmt: str = "auto"
    gyro_path: str | Path | None = None
    acc_unit: str = "auto"
    gyro_unit: str = "auto"
    rate: float | None = 100.0
    sigma_s: float = 0.01
    max_gap: float = 0.2
    on_gap: str = "warn"
    platform: str | None = None
    columns: dict[str, str] | None = field(default=None, hash=False)

    def __post_init__(self) -> None:
        for name, value, allowed in (("fmt", self.fmt, FORMAT_NAMES),
                                     ("acc_unit", self.acc_unit, ("auto", *ACC_UNITS)),
                                     ("gyro_unit", self.gyro_unit, ("auto", *GYRO_UNITS)),
                                     ("on_gap", self.on_gap, ("warn", "raise")),
                                     ("platform", self.platform, (None, *PLATFORMS))):
            if value not in allowed:
                raise UnknownNameError(f"{name} must be one of {list(allowed)}, got {value!r}")
        if self.rate is not None and not (MIN_RATE <= self.rate <= 1000.0):
            raise InputError(f"rate must be between {MIN_RATE:g} and 1000 Hz, got {self.rate}")
        if not (0.0 <= self.sigma_s <= 1.0) or not (self.max_gap > 0):
            raise InputError("sigma_s must be in 0..1 s and max_gap positive")


def read_log(path: str | Path | Sequence[str | Path], placement: str = "right_ankle",
             fmt: str = "auto", *, options: LogOptions | None = None, **kwargs: Any
             ) -> tuple[Recording, LogReport]:
    """Import a phone's sensor log or an IMU's (Xsens) export as a :class:`Recording` in m/s^2
    and rad/s.

    Parameters
    ----------
    path : a log file, an export folder or zip (Sensor Logger, phyphox), or an (accelerometer,
        gyroscope) file pair.
    placement : placement name of the sensor when the file names none (generic multi-sensor
        files name theirs).
    fmt : ``"auto"`` (from the header) or one of :data:`imuloco.io.logformats.FORMATS`.
    options : a :class:`LogOptions`, or its fields as keyword arguments:
        gyro_path : the gyroscope file of formats that split the signals (RealWorld, phyphox).
        acc_unit : ``"auto"``, ``"m/s^2"`` or ``"g"``; gyro_unit : ``"auto"``, ``"rad/s"`` or
        ``"deg/s"``. ``"auto"`` takes the unit a format declares and detects it otherwise.
        rate : model rate in Hz to resample to; ``None`` keeps the aligned irregular samples.
        sigma_s : width of the Gaussian smoothing, seconds (added to resampling's anti-aliasing).
        max_gap : seconds without samples above which a gap is reported.
        on_gap : ``"warn"`` (report, log and interpolate across) or ``"raise"``.
        platform : Sensor Logger only, ``"android"``/``"ios"`` (default: from Metadata.csv, or
        guessed with a warning).
        columns : a CSV's own names of the generic columns
        (:func:`imuloco.io.sensorlog.parse_columns`: ``{"time": "timestamp", "acc_x": "ax"}``),
        read as a generic log.

    Returns
    -------
    The recording (times from 0 s) and a :class:`LogReport`.

    Raises
    ------
    FormatError naming the file (and line) for a file that cannot be read or fails the
    plausibility ranges above (:data:`MIN_RATE` ... :data:`MAX_VALUE`).
    """
    opts = options or LogOptions(placement, fmt, **kwargs)
    first = path if isinstance(path, (str, Path)) else path[0]
    for p in [path] if isinstance(path, (str, Path)) else path:
        if os.path.exists(p) and not (os.path.isfile(p) or os.path.isdir(p)):
            # a FIFO or device would be read for ever
            raise FormatError(p, None, "not a regular file or folder (a FIFO, a device, ...); "
                                       "expected a sensor log")
    try:
        return _import(path, opts)
    except MemoryError:
        raise FormatError(first, None, "too large to import in memory") from None


def _import(path: str | Path | Sequence[str | Path], opts: LogOptions
            ) -> tuple[Recording, LogReport]:
    fmt, streams = _read_streams(path, opts.fmt, None if opts.gyro_path is None
                                 else Path(opts.gyro_path), opts.platform, opts.columns)
    report = LogReport(fmt, sorted({str(s.path) for s in streams}))
    report.platform = next((s.platform for s in streams if s.platform), None)
    sensors = _sensors(streams, opts.placement)
    cleaned = _clean(sensors, report)
    spans = {n: (max(t[0] for t, _ in pair.values()), min(t[-1] for t, _ in pair.values()))
             for n, pair in cleaned.items()}
    files = {n: str(sensors[n]["acc"].path) for n in cleaned}
    check_overlap(spans, files)
    report.sensors = [SensorSource(n, files[n]) for n in cleaned]
    # step 4: the common time interval and reference timestamps (first sensor's accelerometer)
    t0 = max(t[0] for pair in cleaned.values() for t, _ in pair.values())
    t1 = min(t[-1] for pair in cleaned.values() for t, _ in pair.values())
    if t1 - t0 < MIN_DURATION:
        raise FormatError(report.files[0], None, f"the accelerometer and gyroscope cover "
                                                 f"{max(t1 - t0, 0.0):.3g} s together; expected "
                                                 f"at least {MIN_DURATION:g} s")
    ref_t = next(iter(cleaned.values()))["acc"][0]
    times = ref_t[(ref_t >= t0) & (ref_t <= t1)]
    report.gaps = _gaps(cleaned, t0, t1, opts.max_gap)
    report.start_time, report.duration = float(t0), float(t1 - t0)
    report.source_rate = float(1.0 / np.median(np.diff(times)))
    names = list(cleaned)
    signals = {q: np.stack([resample_linear(*cleaned[n][q], times) for n in names], axis=1)
               for q in ("acc", "gyro")}
    for q, unit in (("acc", opts.acc_unit), ("gyro", opts.gyro_unit)):
        declared = {sensors[n][q].unit for n in names} - {None}
        if len(declared) > 1:  # one unit per signal: a mix would be read as one of them
            raise FormatError(report.files[0], None, f"{q}: the sensors' tables declare "
                              f"different units ({', '.join(sorted(declared))}): expected one")
        signals[q], found, detected = _units(signals[q], q, unit, declared)
        setattr(report, f"{q}_unit", found)
        setattr(report, f"{q}_unit_detected", detected)
    if len(report.gaps) == 1:
        g = report.gaps[0]
        log.warning("%s: no samples from %.3f s to %.3f s (%.3f s gap)", report.files[0],
                    g.start, g.stop, g.stop - g.start)
    elif report.gaps:  # one line for the file, not one each (the report lists them all)
        worst = max(report.gaps, key=lambda g: g.stop - g.start)
        log.warning("%s: %d gaps without samples, %.3f s in all, the longest %.3f s from "
                    "%.3f s (each in the report's recording.gaps)", report.files[0],
                    len(report.gaps), sum(g.stop - g.start for g in report.gaps),
                    worst.stop - worst.start, worst.start)
    if report.gaps and opts.on_gap == "raise":
        worst = max(report.gaps, key=lambda g: g.stop - g.start)
        raise FormatError(report.files[0], None, f"{len(report.gaps)} gap(s) longer than "
                          f"{opts.max_gap} s, the longest {worst.stop - worst.start:.3f} s from "
                          f"{worst.start:.3f} s")
    rec = Recording(times - t0, signals["acc"], signals["gyro"], names)
    if opts.rate is not None:  # step 5; gaps were reported above
        rec, _ = resample(rec, opts.rate, sigma_s=opts.sigma_s, max_gap=np.inf)
    return rec, report
