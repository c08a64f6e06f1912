"""The ``xsens`` reader kind of ``imuloco bench --fuzz``: Xsens text exports
(:mod:`imuloco.io.xsens`), read with :func:`~imuloco.sensors.reallog.read_log` as
``reconstruct`` reads them.

Seeds (:func:`xsens_seeds`) are one recording in the three layouts the reader knows: MT
Manager's ASCII export (tab separated, a ``//`` preamble stating 100 Hz, PacketCounter wrapping
at 65,536 and SampleTimeFine at 2^32 within the file, UTC cells empty), the DOT app's CSV
(1 MHz ticks, Gyr in deg/s, no rate stated) and ipol-gait's (the rate line, then PacketCounter
as floats). The structured attacks (:func:`xsens_attack`) break one part: the stated rate (0,
1e-13, 1e23 or 1e400 Hz, or gone), a counter (going back, a jump of 1e15, 1e308, negative, fractional,
constant, empty or NaN cells, random ticks), a signal cell (1e308, inf, NaN, text, empty), the
header (a column duplicated or dropped, pushed past the preamble limit), or the rows (none, one,
ragged, repeated, reversed).
"""

from __future__ import annotations

import random

import numpy as np

from imuloco.lab.mutations import Files

MT_PREAMBLE = ["// Start Time: Unknown", "// Update Rate: 100.0Hz",
               "// Filter Profile: human (46.1)", "// Firmware Version: 4.0.2"]
MT_COLUMNS = ("PacketCounter", "SampleTimeFine", "UTC_Nano", "UTC_Year", "Acc_X", "Acc_Y",
              "Acc_Z", "Gyr_X", "Gyr_Y", "Gyr_Z")
KINDS = ("rate", "counter", "cell", "header", "rows")


def xsens_seeds(acc: np.ndarray, gyro: np.ndarray) -> list[Files]:
    """The three layouts of one sensor's ``acc`` (N, 3) m/s^2 and ``gyro`` (N, 3) rad/s,
    packets at 100 Hz."""
    k = np.arange(len(acc))
    cells = [[f"{v:.6f}" for v in (*a, *g)] for a, g in zip(acc, gyro)]
    mt = ["\t".join(MT_COLUMNS)]
    mt += ["\t".join([f"{(65_400 + i) % 65_536:05d}", str((2**32 - 10_000 + 100 * i) % 2**32),
                      "", "", *c]) for i, c in zip(k, cells)]
    dot = ["sep=,", "DeviceTag:,shoe", "FirmwareVersion:,2.0.0", "",
           "PacketCounter,SampleTimeFine,Euler_X,Acc_X,Acc_Y,Acc_Z,Gyr_X,Gyr_Y,Gyr_Z"]
    dot += [",".join([str(i), str((2**32 - 1_000_000 + 10_000 * i) % 2**32), "179.9",
                      *(f"{v:.6f}" for v in (*a, *np.degrees(g)))])
            for i, a, g in zip(k, acc, gyro)]
    ipol = ["Acquisition frequency: 100 Hz",
            "PacketCounter\tAcc_X\tAcc_Y\tAcc_Z\tGyr_X\tGyr_Y\tGyr_Z"]
    ipol += ["\t".join([f"{float((65_400 + i) % 65_536)}", *c]) for i, c in zip(k, cells)]
    return [{"mt.txt": _text(MT_PREAMBLE + mt)}, {"dot.csv": _text(dot)},
            {"ipol.txt": _text(ipol)}]


def _text(lines: list[str]) -> bytes:
    return ("\n".join(lines) + "\n").encode()


def xsens_attack(files: Files, rng: random.Random) -> tuple[str, Files]:
    """One structured attack (module docstring) on the seed's one file."""
    name, data = next(iter(files.items()))
    lines = data.decode().splitlines()
    at = next(i for i, ln in enumerate(lines) if "Acc_X" in ln)
    sep = "\t" if "\t" in lines[at] else ","
    pre, header, rows = lines[:at], lines[at].split(sep), [r.split(sep) for r in lines[at + 1:]]
    kind = rng.choice(KINDS)
    if kind == "rate":
        label, value = rng.choice((("0", "0"), ("1e-13", "0.0000000000001"),
                                   ("1e23", "1" + "0" * 23), ("1e400", "1" + "0" * 400),
                                   ("gone", None)))
        rated = [i for i, ln in enumerate(pre) if "Hz" in ln or "frequency" in ln]
        for i in rated:
            pre[i] = pre[i] if value is None else pre[i].split(":")[0] + f": {value} Hz"
        pre = [ln for i, ln in enumerate(pre) if value is not None or i not in rated]
        kind += f"-{label}"
    elif kind == "counter":
        col = rng.choice([c for c in ("PacketCounter", "SampleTimeFine") if c in header])
        kind = f"{col}-{_counter_attack(rows, header.index(col), rng)}"
    elif kind == "cell":
        value = rng.choice(("1e308", "-1e308", "inf", "nan", "abc", ""))
        row, col = rng.randrange(len(rows)), header.index(rng.choice(("Acc_X", "Gyr_Z")))
        rows[row][col] = value
        kind += f"-{value or 'empty'}"
    elif kind == "header":
        op = rng.choice(("duplicate", "drop", "late"))
        if op == "duplicate":
            header[header.index("Gyr_Y")] = "Acc_X"
        elif op == "drop":
            header.remove("Gyr_Z")
        else:
            pre = [f"// note {i}" for i in range(rng.choice((99, 100, 150)))] + pre
        kind += f"-{op}"
    else:
        op = rng.choice(("none", "one", "ragged", "repeat", "reverse"))
        if op in ("none", "one"):
            rows = rows[: op == "one"]
        elif op == "ragged":
            k = rng.randrange(len(rows))
            rows[k] = rows[k][: rng.randrange(len(rows[k]))]
        elif op == "repeat":
            rows = rows * 3
        else:
            rows = rows[::-1]
        kind += f"-{op}"
    return f"attack:{kind}", {name: _text(pre + [sep.join(header)]
                                          + [sep.join(r) for r in rows])}


def _counter_attack(rows: list[list[str]], col: int, rng: random.Random) -> str:
    """Break the counter in column ``col`` of ``rows`` in place; returns how."""
    op = rng.choice(("back", "jump", "huge", "negative", "fraction", "constant", "empty",
                     "nan", "random"))
    k = rng.randrange(1, len(rows))
    if op == "back":
        rows[k][col] = rows[k - 1][col]
        rows[k - 1][col] = str(float(rows[k][col]) + 5)
    elif op == "jump":
        for r in rows[k:]:
            r[col] = str(int(float(r[col])) + 10**15)
    elif op in ("huge", "negative", "fraction", "empty", "nan"):
        rows[k][col] = {"huge": "1e308", "negative": "-3", "fraction": "12.5", "empty": "",
                        "nan": "nan"}[op]
    elif op == "constant":
        for r in rows:
            r[col] = rows[0][col]
    else:
        for r in rows:
            r[col] = str(rng.randrange(2**32))
    return op
