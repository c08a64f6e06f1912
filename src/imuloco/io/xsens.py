"""Xsens text exports: one sensor's accelerometer and gyroscope per file.

Layouts (tab, comma or semicolon separated; a preamble of up to :data:`MAX_PREAMBLE` lines,
then a header naming the outputs, then one line per packet):

- MT Manager's ASCII export (MTi, MTw Awinda): ``//`` lines (``// Update Rate: 100.0Hz``,
  ``// Filter Profile: human (46.1)``, ``// Firmware Version: ...``; MT Manager 2022 indents
  them under ``// Device settings:``), then ``PacketCounter  SampleTimeFine  Year ...  Acc_X
  Acc_Y  Acc_Z  Gyr_X ...``. Outputs a packet lacks are empty cells (an MTw's SampleTimeFine
  and UTC columns often are: OpenSim OpenSense's example MTw files).
- ipol-gait's files (``shared/data/real-imu/ipol-gait``): ``Acquisition frequency: 100 Hz``,
  then ``PacketCounter Acc_X Acc_Y Acc_Z Gyr_X Gyr_Y Gyr_Z Mag_X ...``.
- The Xsens (Movella) DOT app's CSV: ``sep=,``, ``DeviceTag:,...``, optionally
  ``OutputRate:,60Hz``, then ``PacketCounter,SampleTimeFine,Euler_X,...,Acc_X,...,Gyr_X,...``.

Times: ``SampleTimeFine`` when every line has one, unwrapped at 2^32. MTi User Manual (MT0605P,
sec. 4.12.3): a 4-byte time stamp of 0.1 ms resolution (10 kHz ticks); Xsens DOT User Manual
(XD0502P, sec. 4.2.5): 1 MHz ticks, wrapping at 0xFFFFFFFF. The tick is the one whose sampling rate
is nearer the rate the preamble states; without a stated rate 10 kHz, unless a median step over
2,000 ticks would make that slower than 5 Hz (a DOT's 120 Hz, its fastest, steps 8,333 us).
Otherwise ``PacketCounter`` (16-bit, wrapping at 65,536, on an MTi or MTw; 32-bit on a DOT) over
the stated rate; dropped packets leave gaps in either. Neither: refused.

Units are left to :mod:`imuloco.sensors.reallog`'s detection: MT Manager writes ``Acc`` in m/s^2
and ``Gyr`` in rad/s, the DOT app ``Acc`` in m/s^2 and ``Gyr`` in degree/s (DOT User Manual
XD0502P, sec. 4.2.2, Table 9). Other columns (magnetometer, orientation, ``FreeAcc`` without
gravity, status) are ignored; a non-numeric cell is refused with its line.
"""

from __future__ import annotations

import math
import re
from itertools import islice
from pathlib import Path

import numpy as np

from imuloco.errors import FormatError, excerpts
from imuloco.io.sensorlog import Stream, _read_table, _sniff, _split, _text_lines

MAX_PREAMBLE = 100  # lines before the header (the exports seen: MT Manager 2022 12, DOT app 11)
ACC = ("Acc_X", "Acc_Y", "Acc_Z")
GYR = ("Gyr_X", "Gyr_Y", "Gyr_Z")
_HEADER_NAMES = {"PacketCounter", "SampleTimeFine", *ACC, *GYR}
# the rate lines: ipol-gait's, MT Manager's (``//`` and indented) and the DOT app's
_RATE = re.compile(r"^\s*(?://)?\s*(?:acquisition frequency|update rate|output ?rate)\s*:"
                   r"[\s,]*([0-9]*\.?[0-9]+)\s*hz", re.IGNORECASE)
TICKS_HZ = (1e4, 1e6)  # SampleTimeFine: MTi / MTw (10 kHz), DOT (1 MHz)
MAX_10KHZ_STEP = 2000  # ticks: 5 Hz (reallog.MIN_RATE) at 10 kHz
COUNTER_PERIODS = (65536.0, 2.0**32)  # PacketCounter: MTi / MTw (16-bit), DOT (32-bit)


def stated_rate(line: str) -> float | None:
    """The rate in Hz a preamble line states (``Acquisition frequency: 100 Hz``, ``// Update
    Rate: 100.0Hz``, ``OutputRate:,60Hz``), or None."""
    m = _RATE.match(line.lstrip("\ufeff"))
    return float(m.group(1)) if m else None


def unwrap_counter(counter: np.ndarray, period: float = 65536.0) -> np.ndarray:
    """A counter that wraps at ``period`` (Xsens's 16-bit PacketCounter by default) made
    monotonic across its wraps: a step back by more than half the period is a wrap."""
    step = np.diff(counter)
    return counter[0] + np.concatenate([[0.0], np.cumsum(np.where(step < -period / 2,
                                                                  step + period, step))])


def find_header(path: str | Path) -> tuple[int, float | None] | None:
    """(line of the Xsens header, the rate stated above it or None), or None when none of the
    first :data:`MAX_PREAMBLE` lines names PacketCounter, SampleTimeFine, Acc_X.. or Gyr_X.."""
    path = Path(path)
    rate = None
    with open(path, "rb") as f:
        for i, line in islice(_text_lines(path, f), MAX_PREAMBLE):
            found = stated_rate(line)
            if found is not None:
                rate = found
            elif _HEADER_NAMES & {c.strip() for c in _split(path, i, line, _sniff(line)[0])}:
                return i, rate
    return None


def is_xsens(path: str | Path) -> bool:
    """Whether ``path`` has an Xsens header within its first lines (an unreadable line: no)."""
    try:
        return find_header(path) is not None
    except FormatError:
        return False


def read_xsens(path: str | Path) -> list[Stream]:
    """The accelerometer and gyroscope streams of an Xsens text export (module docstring)."""
    path = Path(path)
    found = find_header(path)
    if found is None:
        raise FormatError(path, None, f"expected an Xsens header (PacketCounter, SampleTimeFine, "
                                      f"Acc_X..., Gyr_X...) within the first {MAX_PREAMBLE} lines")
    line, rate = found
    if rate is not None and not math.isfinite(rate):  # hundreds of digits overflow a float
        raise FormatError(path, line, "the rate stated above the header is no finite number of "
                                      "Hz")
    header, data, lines = _read_table(path, allow_empty=True, skip=line - 1)
    missing = [c for c in ACC + GYR if c not in header]
    if missing:
        hint = (" (FreeAcc is acceleration without gravity: export Acc, the calibrated "
                "acceleration, and Gyr)" if "FreeAcc_X" in header else "")
        raise FormatError(path, line, f"missing column(s) {missing}: expected Acc_X, Acc_Y, "
                                      f"Acc_Z, Gyr_X, Gyr_Y, Gyr_Z; found {excerpts(header)}{hint}")
    signals = data[:, [header.index(c) for c in ACC + GYR]]
    if np.isnan(signals).any():
        row, col = (int(k[0]) for k in np.nonzero(np.isnan(signals)))
        raise FormatError(path, int(lines[row]), f"column {(ACC + GYR)[col]!r} is empty: "
                                                 "expected a number")
    times = _times(path, line, header, data, lines, rate)
    return [Stream(path, "acc", times, signals[:, :3], None, None, lines),
            Stream(path, "gyro", times, signals[:, 3:], None, None, lines)]


def _times(path: Path, line: int, header: list[str], data: np.ndarray, lines: np.ndarray,
           rate: float | None) -> np.ndarray:
    """Seconds of each row: SampleTimeFine, else PacketCounter over the stated rate."""
    why = []
    for name in ("SampleTimeFine", "PacketCounter"):
        if name not in header:
            why.append(f"no {name} column")
            continue
        values = data[:, header.index(name)]
        if np.isnan(values).any():
            why.append(f"{name} empty on line {int(lines[np.argmax(np.isnan(values))])}")
            continue
        if name == "PacketCounter" and not rate:
            why.append("no rate stated above the header")
            continue
        period = COUNTER_PERIODS[0] if name == "PacketCounter" and values.max() < \
            COUNTER_PERIODS[0] else COUNTER_PERIODS[1]
        ticks = _counter(path, name, values, lines, period)
        if name == "PacketCounter":
            return ticks / rate
        steps = np.diff(ticks)
        step = float(np.median(steps[steps > 0])) if (steps > 0).any() else 1.0
        if rate:
            tick = min(TICKS_HZ, key=lambda hz: abs(math.log(hz / step / rate)))
        else:
            tick = TICKS_HZ[0] if step <= MAX_10KHZ_STEP else TICKS_HZ[1]
        return ticks / tick
    raise FormatError(path, line, "no sample times: expected a SampleTimeFine value on every "
                                  "line, or PacketCounter with the rate stated above the header "
                                  "('// Update Rate: 100.0Hz' or 'Acquisition frequency: 100 "
                                  f"Hz'); found {', '.join(why)}")


def _counter(path: Path, name: str, values: np.ndarray, lines: np.ndarray, period: float
             ) -> np.ndarray:
    """``values`` of a wrapping counter (whole numbers in 0..period-1), unwrapped; refused
    with its line where it is out of range or goes back (a restarted recording)."""
    bad = (values < 0) | (values >= period) | (values != np.round(values))
    if bad.any():
        k = int(np.argmax(bad))
        raise FormatError(path, int(lines[k]), f"{name}: expected a whole number in 0-"
                                               f"{period - 1:.0f}, got {values[k]:g}")
    ticks = unwrap_counter(values, period)
    back = np.diff(ticks) < 0
    if back.any():
        k = int(np.argmax(back)) + 1
        raise FormatError(path, int(lines[k]), f"{name} goes back from {values[k - 1]:.0f} to "
                                               f"{values[k]:.0f}: expected increasing "
                                               "values (one recording per file)")
    return ticks
