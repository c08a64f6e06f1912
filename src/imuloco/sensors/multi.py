"""Several sensors from several files: one recording on one clock.

``imuloco reconstruct LOG --sensor left_wrist=WATCH.csv`` reads the log (its own sensors, e.g.
a Sensor Logger export with its watch) and each further file at its placement
(:func:`read_sensors`), then puts every further sensor on the log's clock:

- **timestamps**: when both files carry absolute (Unix) times (phones, Sensor Logger, most
  apps), they are taken as one clock (devices synchronised by the network, to milliseconds);
- **xcorr** otherwise (a device counting from its own start), by the rule the user follows:
  *start every device, stand still, stomp twice, then move*. The jolt of a stomp reaches every
  sensor at once; on each sensor the two stomps are the first two jolts after a still stretch
  (:func:`_stomps`), their spacings must agree, and the cross-correlation of both sensors'
  jolts over the stomps refines the offset the first stomps give (:func:`align_by_xcorr`).
  Offsets up to :data:`MAX_OFFSET_S` are found, either device starting first.

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
from typing import NamedTuple

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
XCORR_WINDOW_S = 5.0  # seconds from the later sensor's start that hold the two stomps
QUIET_S = 0.25  # the stand: its quietest stretch this long gives the noise; a stomp follows one
JOLT_TIMES = 10.0  # a stomp's jolt stands this many times out of the stand's noise (RMS)
NOISE_FLOOR = 0.01  # m/s^2 a sample: the least noise assumed (a noiseless simulation has none)
ONE_JOLT_S = 0.15  # jolts closer than this are one stomp
SPACING_S = (0.3, 2.0)  # the two stomps are this far apart, seconds (deliberate stomps)
SPACING_TOL_S = 0.05  # their spacing agrees on both sensors within this
REFINE_S = 0.1  # the first stomps give the offset to within this; the correlation refines it
MAX_OFFSET_S = 10.0  # largest clock offset searched, seconds
MIN_CORRELATION = 0.6  # a weaker peak is no match: refused, asking for a stomp at the start


class Alignment(NamedTuple):
    """Where ``other``'s clock sits on ``ref``'s (:func:`align_by_xcorr`)."""

    shift_s: float  # seconds added to other's times (from its start) to put them on ref's
    correlation: float  # normalised cross-correlation of both sensors' jolts there (1: same)
    problem: str | None = None  # why there is no alignment (shift NaN), else None


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
    """The change of sensor ``k``'s acceleration magnitude from sample to sample (the norm
    high-passed by a first difference), m/s^2, shape (T - 1,): a stomp's jolt changes it
    within a few samples on every sensor at once, while the limbs' swing changes it slowly."""
    return np.diff(np.linalg.norm(rec.acc[:, k], axis=-1))


def _stomps(jolts: np.ndarray, n: int, dt: float) -> tuple[int, int] | str:
    """The onsets (sample indices) of the two stomps among the first ``n`` samples of
    ``jolts``, shape (T - 1,), or why they were not found.

    The noise is the jolts' RMS over the quietest :data:`QUIET_S` (the stand; the median of
    the whole head would be the motion's when it starts early and is vigorous, as a run's
    is); a jolt stands :data:`JOLT_TIMES` times out of it. Jolts closer than
    :data:`ONE_JOLT_S` are one event; the stomps are the first two events at most
    :data:`SPACING_S` apart of which the first follows :data:`QUIET_S` of stand."""
    head = jolts[:n]
    q = max(round(QUIET_S / dt), 1)
    if len(head) < 2 * q:
        return f"shorter than {2 * QUIET_S:g} s"
    power = np.convolve(head * head, np.ones(q) / q, mode="valid")  # moving mean square
    noise = max(float(np.sqrt(power.min())), NOISE_FLOOR)
    big = np.flatnonzero(np.abs(head) > JOLT_TIMES * noise)
    if len(big) == 0:
        return "no jolt stands out of the stand's noise"
    onsets = big[np.concatenate([[True], np.diff(big) * dt > ONE_JOLT_S])]
    quiet_before = np.concatenate([[onsets[0] >= q], np.diff(onsets) >= q])
    for i in range(len(onsets) - 1):
        gap = (onsets[i + 1] - onsets[i]) * dt
        if quiet_before[i] and SPACING_S[0] <= gap <= SPACING_S[1]:
            return int(onsets[i]), int(onsets[i + 1])
    return (f"no two jolts {SPACING_S[0]:g}-{SPACING_S[1]:g} s apart after {QUIET_S:g} s "
            "of standing still")


def _refine(a: np.ndarray, b: np.ndarray, ia: int, b0: int, b1: int, m: int
            ) -> tuple[float, float]:
    """The lag (samples, fractional) within ``-m..m`` of ``a[ia + j]`` matching ``b[b0 + j]``
    best over ``b[b0:b1]``, and the normalised cross-correlation there (by both stretches'
    energies; the peak refined between samples by a parabola through it and its
    neighbours)."""
    bw = b[b0:b1]
    start = ia - m
    pad = max(-start, 0)
    aw = np.pad(a, (pad, len(bw) + 2 * m))[start + pad:start + pad + len(bw) + 2 * m]
    c = correlate(aw, bw, mode="valid", method="fft")  # lags -m .. m
    energy = np.concatenate([[0.0], np.cumsum(aw * aw)])
    local = energy[len(bw):len(bw) + len(c)] - energy[:len(c)]
    c = c / np.sqrt(np.maximum(local, 1e-12) * max(float(np.sum(bw * bw)), 1e-12))
    i = int(np.argmax(c))
    frac = 0.0
    if 0 < i < len(c) - 1:
        y0, y1, y2 = c[i - 1], c[i], c[i + 1]
        den = y0 - 2 * y1 + y2
        frac = 0.5 * (y0 - y2) / den if den < 0 else 0.0
    return i - m + frac, float(c[i])


def align_by_xcorr(ref: Recording, other: Recording, k_ref: int = 0, k_other: int = 0,
                   window_s: float = XCORR_WINDOW_S, max_offset_s: float = MAX_OFFSET_S
                   ) -> Alignment:
    """Where ``other``'s clock sits on ``ref``'s, by the two stomps at the start (the rule:
    stand still, stomp twice, then move).

    Both recordings are uniformly sampled at the same rate (:func:`imuloco.sensors.reallog.
    read_log` resamples them). On each sensor (``k_ref``, ``k_other``) the two stomps are
    found in the jolts (:func:`_jolts`) of its first ``window_s + max_offset_s`` seconds
    (either device may have started first) by :func:`_stomps`; their spacings must agree
    within :data:`SPACING_TOL_S` (a lone jolt or a step taken for a stomp does not), the
    first stomps give the offset, and the cross-correlation of the jolts over both stomps
    refines it within :data:`REFINE_S` (:func:`_refine`). An offset beyond
    ``max_offset_s`` is none.
    """
    dt = float(np.median(np.diff(ref.times)))
    a, b = _jolts(ref, k_ref), _jolts(other, k_other)
    n = round((window_s + max_offset_s) / dt)
    sa, sb = _stomps(a, n, dt), _stomps(b, n, dt)
    for found, which in ((sa, "the first file"), (sb, "this file")):
        if isinstance(found, str):
            return Alignment(float("nan"), 0.0, f"no two stomps found in {which}: {found}")
    (a0, a1), (b0, b1) = sa, sb
    if abs((a1 - a0) - (b1 - b0)) * dt > SPACING_TOL_S:
        return Alignment(float("nan"), 0.0, f"the two stomps are {(a1 - a0) * dt:.2f} s apart "
                         f"in the first file, {(b1 - b0) * dt:.2f} s in this one")
    m = max(round(REFINE_S / dt), 1)
    lo, hi = max(b0 - m, 0), min(b1 + 2 * m, len(b))  # both stomps, a little either side
    lag, corr = _refine(a, b, a0 - (b0 - lo), lo, hi, m)
    shift = (a0 - b0 + lag) * dt + ref.times[0] - other.times[0]
    if abs(shift) > max_offset_s:
        return Alignment(float("nan"), corr, f"the stomps are {shift:+.1f} s apart, beyond "
                         f"+-{max_offset_s:g} s")
    return Alignment(float(shift), corr)


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
        shift, corr, problem = align_by_xcorr(rec, extra)
        offset = shift + report.start_time - extra_report.start_time
        if problem is None and not corr >= MIN_CORRELATION:
            problem = (f"the jolts of the two stomps correlate at most {corr:.2f} (at "
                       f"{offset:+.3f} s; expected at least {MIN_CORRELATION})")
        if problem is not None:
            raise FormatError(file, None, f"its clock could not be aligned with "
                              f"{report.files[0]}'s: {problem}: record with the clocks of one "
                              "phone, or start every device, stand still, stomp twice, then "
                              "move")
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
