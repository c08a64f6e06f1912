"""Several sensors from several files: one recording on one clock.

``imuloco reconstruct LOG --sensor left_wrist=WATCH.csv`` reads the log (its own sensors, e.g.
a Sensor Logger export with its watch) and each further file at its placement
(:func:`read_sensors`), then puts every further sensor on the log's clock:

- **timestamps**: when both files carry absolute (Unix) times (phones, Sensor Logger, most
  apps), they are taken as one clock (devices synchronised by the network, to milliseconds);
- **xcorr** otherwise (a device counting from its own start): the offset that best matches the
  two sensors' acceleration magnitudes over the first :data:`XCORR_WINDOW_S` seconds, by
  cross-correlation (:func:`align_by_xcorr`). The rule the user follows: stand still, stomp
  (or clap, for wrist sensors) once or twice at the start; the jolt reaches every sensor at
  once and gives the correlation one sharp peak. Offsets up to :data:`MAX_OFFSET_S` are found.

The sensors must then record together :data:`imuloco.sensors.reallog.MIN_OVERLAP` of the
shortest one's span (:func:`imuloco.sensors.reallog.check_overlap`), or the recording is
refused naming them. Each sensor's file, offset, rule and correlation peak go to the report's
``sensors`` (:class:`imuloco.sensors.reallog.SensorSource`).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.signal import correlate

from imuloco.core.recording import Recording
from imuloco.errors import FormatError, InputError
from imuloco.ops.filters import resample_linear
from imuloco.sensors.placement import get_placement
from imuloco.sensors.reallog import (
    LogOptions,
    LogReport,
    SensorSource,
    check_overlap,
    read_log,
)
from imuloco.sensors.resample import Gap

log = logging.getLogger(__name__)

UNIX_AFTER_S = 1e8  # a file whose clock reads more (1973 on) carries Unix time
XCORR_WINDOW_S = 5.0  # seconds from a sensor's start that hold the first stomp
JOLT_TIMES = 10.0  # a stomp's jolt stands this many times out of the still stand's noise
REFINE_S = 0.25  # the first stomps give the offset to within this; the correlation refines it
STOMP_WINDOW_S = 2.0  # seconds of jolts compared, from the first stomp on
MAX_OFFSET_S = 10.0  # largest clock offset searched, seconds
MIN_CORRELATION = 0.3  # a weaker peak is no match: refused, asking for a stomp at the start


def parse_sensor(text: str) -> tuple[str, Path]:
    """``"left_wrist=watch.csv"`` as ``("left_wrist", Path("watch.csv"))``; the placement
    must be a preset."""
    name, sep, file = (p.strip() for p in text.partition("="))
    if not sep or not name or not file:
        raise InputError(f"--sensor {text!r}: expected PLACEMENT=FILE, e.g. "
                         "left_wrist=watch.csv")
    get_placement(name)  # UnknownNameError naming the presets
    return name, Path(file)


def _jolts(rec: Recording, k: int) -> np.ndarray:
    """The change of sensor ``k``'s acceleration magnitude from sample to sample, m/s^2,
    shape (T - 1,): a stomp's jolt changes it within a few samples on every sensor at once,
    while the limbs' swing changes it slowly."""
    return np.diff(np.linalg.norm(rec.acc[:, k], axis=-1))


def _first_jolt(jolts: np.ndarray, n: int) -> int | None:
    """Index of the first of the first ``n`` samples of ``jolts`` beyond :data:`JOLT_TIMES`
    times their median size (the still stand's noise): the first stomp; None if none."""
    head = np.abs(jolts[:n])
    big = np.flatnonzero(head > JOLT_TIMES * max(float(np.median(head)), 1e-6))
    return int(big[0]) if len(big) else None


def align_by_xcorr(ref: Recording, other: Recording, k_ref: int = 0, k_other: int = 0,
                   window_s: float = XCORR_WINDOW_S, max_offset_s: float = MAX_OFFSET_S
                   ) -> tuple[float, float]:
    """The seconds to add to ``other``'s times to put them on ``ref``'s, and the normalised
    cross-correlation there (1: the same jolts on both); NaN and 0 when a sensor shows no
    stomp.

    Both recordings are uniformly sampled at the same rate (:func:`imuloco.sensors.reallog.
    read_log` resamples them). On each sensor (``k_ref``, ``k_other``) the first stomp is the
    first jolt (:func:`_jolts`) within the first ``window_s`` seconds standing out of the
    still stand's noise (:func:`_first_jolt`); the two stomps give the offset to within
    :data:`REFINE_S`, and the cross-correlation of the jolts over :data:`STOMP_WINDOW_S`
    from there refines it (normalised by the two stretches' energies; the peak refined
    between samples by a parabola through it and its neighbours).
    """
    dt = float(np.median(np.diff(ref.times)))
    a, b = _jolts(ref, k_ref), _jolts(other, k_other)
    n = round(window_s / dt)
    ia, ib = _first_jolt(a, n + round(max_offset_s / dt)), _first_jolt(b, n)
    if ia is None or ib is None:
        return float("nan"), 0.0
    m = round(REFINE_S / dt)
    w = round(STOMP_WINDOW_S / dt)
    lo = max(ib - m, 0)
    bw = b[lo:lo + w]  # other's stomps, from a little before the first
    start = ia - (ib - lo) - m  # ref's index matching bw[0] at lag -m
    pad = max(-start, 0)
    aw = np.pad(a, (pad, w + 2 * m))[start + pad:start + pad + len(bw) + 2 * m]
    c = correlate(aw, bw, mode="valid", method="fft")  # lags -m .. m around the stomps'
    energy = np.concatenate([[0.0], np.cumsum(aw * aw)])
    local = energy[len(bw):len(bw) + len(c)] - energy[:len(c)]
    c = c / np.sqrt(np.maximum(local, 1e-12) * max(float(np.sum(bw * bw)), 1e-12))
    i = int(np.argmax(c))
    frac = 0.0
    if 0 < i < len(c) - 1:
        y0, y1, y2 = c[i - 1], c[i], c[i + 1]
        den = y0 - 2 * y1 + y2
        frac = 0.5 * (y0 - y2) / den if den < 0 else 0.0
    lag = (ia - ib + i - m + frac) * dt + ref.times[0] - other.times[0]
    if abs(lag) > max_offset_s:
        return float("nan"), 0.0
    return float(lag), float(c[i])


def _merge(rec: Recording, report: LogReport, extra: Recording, extra_report: LogReport,
           placement: str, file: Path, align: str) -> tuple[Recording, LogReport]:
    """``extra`` (one sensor) put on ``rec``'s clock and added to it."""
    if placement in rec.placements:
        raise InputError(f"--sensor {placement}={file}: the recording already has a sensor at "
                         f"{placement} ({report.files[0]})")
    unix = min(report.start_time, extra_report.start_time) > UNIX_AFTER_S
    if align == "auto":
        align = "timestamps" if unix else "xcorr"
    corr = None
    if align == "timestamps":
        shift = extra_report.start_time - report.start_time  # extra's time 0 on rec's time line
        offset = 0.0
    else:
        shift, corr = align_by_xcorr(rec, extra)
        offset = shift + report.start_time - extra_report.start_time
        if not corr >= MIN_CORRELATION:
            raise FormatError(file, None, f"its clock could not be aligned with "
                              f"{report.files[0]}'s: the acceleration magnitudes correlate at "
                              f"most {corr:.2f} (at {offset:+.3f} s; expected at least "
                              f"{MIN_CORRELATION}): record with the clocks of one phone, or "
                              "stand still and stomp twice at the start of the recording")
    spans = {**{p: (0.0, float(rec.times[-1])) for p in rec.placements},
             placement: (shift, shift + float(extra.times[-1]))}
    check_overlap(spans, {**{p: report.files[0] for p in rec.placements},
                          placement: str(file)})
    t0, t1 = max(0.0, shift), min(float(rec.times[-1]), shift + float(extra.times[-1]))
    keep = (rec.times >= t0) & (rec.times <= t1)
    times = rec.times[keep]
    acc = resample_linear(extra.times + shift, extra.acc[:, 0], times)[:, None]
    gyro = resample_linear(extra.times + shift, extra.gyro[:, 0], times)[:, None]
    merged = Recording(times - t0, np.concatenate([rec.acc[keep], acc], axis=1),
                       np.concatenate([rec.gyro[keep], gyro], axis=1),
                       [*rec.placements, placement])
    gaps = [Gap(max(g.start + a, 0.0), min(g.stop + a, t1 - t0))
            for gs, a in ((report.gaps, -t0), (extra_report.gaps, shift - t0)) for g in gs]
    source = SensorSource(placement, str(file), offset, align, corr)
    out = replace(report, files=[*report.files, *extra_report.files],
                  samples={q: report.samples.get(q, 0) + extra_report.samples.get(q, 0)
                           for q in ("acc", "gyro")},
                  start_time=report.start_time + t0, duration=t1 - t0,
                  gaps=sorted((g for g in gaps if g.stop > g.start), key=lambda g: g.start),
                  sensors=[*report.sensors, source])
    log.info("%s at %s: clock offset %+.3f s (%s%s)", file, placement, offset, align,
             "" if corr is None else f", correlation {corr:.2f}")
    return merged, out


def read_sensors(path, sensors: Sequence[tuple[str, str | Path]] = (), *,
                 options: LogOptions | None = None, align: str = "auto", **kwargs
                 ) -> tuple[Recording, LogReport]:
    """The log at ``path`` (:func:`imuloco.sensors.reallog.read_log`, its options as keyword
    arguments or ``options``) with each ``(placement, file)`` of ``sensors`` read at its
    placement and put on the log's clock (see the module docstring).

    align : ``"auto"`` (timestamps when both files carry Unix times, else cross-correlation),
        ``"timestamps"`` or ``"xcorr"``.
    """
    if align not in ("auto", "timestamps", "xcorr"):
        raise InputError(f"align must be auto, timestamps or xcorr, got {align!r}")
    opts = options or LogOptions(**kwargs)
    rec, report = read_log(path, options=opts)
    for placement, file in sensors:
        extra, extra_report = read_log(file, options=replace(
            opts, placement=placement, fmt="auto", gyro_path=None, columns=None))
        if extra.placements != [placement]:
            raise FormatError(file, None, f"--sensor {placement}=FILE reads one sensor; the "
                                          f"file holds {extra.placements}")
        rec, report = _merge(rec, report, extra, extra_report, placement, Path(file), align)
    return rec, report
