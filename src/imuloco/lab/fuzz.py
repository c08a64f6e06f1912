"""Fuzzing the readers: generated malformed inputs, each read with a time limit.

``imuloco bench --fuzz N`` runs :func:`run_fuzz`: for each reader (BVH, ASF/AMC, sensor-log
tables, :func:`~imuloco.sensors.reallog.read_log`, model files, the real-data folders of
:func:`~imuloco.io.realimu.read_trials`: :mod:`imuloco.lab.fuzz_real`, Xsens text exports
read by ``read_log``: :mod:`imuloco.lab.fuzz_xsens`) it builds small
valid files from the bundled sample (:func:`seed_files`), derives N inputs from them by random
mutation (bytes, lines, cells) and by the structured attacks of issue 18 (a timestamp jumping by days, rows a
nanosecond apart, cells of 1e308, ``Frame Time`` of 1000 s, 20,000 nested joints, ASF units of
5e-324, forged array shapes, decompression bombs, deep JSON headers, ...) and those of issue 42
(:mod:`imuloco.lab.fuzz_structure`: structure-aware BVH and AMC, zip-member bombs, output
targets; every input of these readers is such an attack), and reads each in a worker
process. Every outcome is one of :data:`OUTCOMES`:

clean
    the library's own error (:class:`~imuloco.errors.ImulocoError`) whose message names the
    file (its name appears in the message);
accepted
    read, and the result is plausible;
wrong exception type
    any other exception (``ValueError``, ``MemoryError``, ...), or a library error that does
    not name the file;
hang
    no answer within ``timeout`` seconds (the worker is killed and replaced);
garbage accepted
    read, but the result is implausible (:func:`garbage`): a frame rate outside 1-1000 fps,
    non-finite numbers, no frames or samples, a recording whose length does not match its
    sample count, a model whose header fails :func:`~imuloco.methods.modelfile.check_header`
    or whose reconstruction of a short signal is not finite.

Workers run with an address-space limit (``RLIMIT_AS``, 4 GiB) so that a runaway allocation
ends as a ``MemoryError`` (counted as a wrong exception type) instead of taking the machine.
"""

from __future__ import annotations

import importlib.util
import io
import itertools
import json
import logging
import multiprocessing as mp
import os
import platform as host
import random
import resource
import shutil
import tempfile
import time
import warnings
import zipfile
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from imuloco.core.recording import Recording
from imuloco.data import MODELS_DIR, SAMPLE_DIR
from imuloco.errors import ImulocoError
from imuloco.io.asf_amc import read_asf_amc
from imuloco.io.atomic import atomic_write
from imuloco.io.bvh import read_bvh
from imuloco.io.database import load_sample
from imuloco.io.sensorlog import (
    read_generic_csv,
    read_phyphox,
    read_sensor_logger,
    write_generic_csv,
)
from imuloco.lab.fuzz_exports import _zip, export_attack, export_garbage, export_seeds, read_export
from imuloco.lab.fuzz_live import live_attack, live_garbage, live_method, live_seeds, play
from imuloco.lab.fuzz_real import read_real, real_attack, real_garbage, real_seeds
from imuloco.lab.fuzz_structure import (
    amc_structure_attack,
    bvh_structure_attack,
    output_attack,
    output_garbage,
    output_seeds,
    write_outputs,
    zip_member_attack,
)
from imuloco.lab.fuzz_xsens import xsens_attack, xsens_seeds
from imuloco.methods import get_method, load_model, method_class
from imuloco.methods.modelfile import check_header, non_finite
from imuloco.sensors.reallog import read_log
from imuloco.sensors.simulate import simulate

READERS = ("bvh", "asf", "sensorlog", "read_log", "model", "model_header", "real", "xsens",
           "bvh-structure", "amc-structure", "zip-members", "outputs", "exports", "live")
READER_TITLES = {"bvh": "BVH", "asf": "ASF/AMC", "sensorlog": "sensor-log tables",
                 "read_log": "`read_log`", "model": "model files",
                 "model_header": "model headers (JSON values)",
                 "real": "real-data folders (`read_trials`)",
                 "xsens": "Xsens exports (`read_log`)",
                 "bvh-structure": "BVH, structure-aware", "amc-structure": "AMC, structure-aware",
                 "zip-members": "zip members (`read_log`)",
                 "outputs": "output targets (`check_outputs`, `OutputSet`)",
                 "exports": "phone exports: units, zip folders, links (`read_log`)",
                 "live": "live server messages and requests (loopback)"}
# readers of issue 42's classes (lab/fuzz_structure.py): every input a structured attack,
# read as the reader they stand for
STRUCTURED = {"bvh-structure": "bvh", "amc-structure": "asf", "zip-members": "read_log",
              "outputs": "outputs"}
OUTCOMES = ("clean", "accepted", "wrong exception type", "hang", "garbage accepted")
MEMORY_LIMIT = 4 << 30  # bytes of address space per worker

Files = dict[str, bytes]  # file name -> content; the first file is the one read


@dataclass(frozen=True)
class Case:
    """One generated input: its files and the mutation that made it."""

    reader: str
    mutation: str
    files: tuple[tuple[str, bytes], ...]


# ---------------------------------------------------------------------------------------------
# valid seeds from the bundled sample

def seed_files(work: Path) -> dict[str, list[Files]]:
    """Small valid inputs per reader, made from the bundled sample in ``work``."""

    bvh_path = min(Path(SAMPLE_DIR).glob("*.bvh"))
    bvh = _cut_bvh(bvh_path.read_text(), 40).encode()
    db = load_sample()
    clip = db.where(content="walk").clips[0]
    rec = simulate(clip, ["right_ankle"], 100.0, "phone", 3)
    keep = rec.times <= rec.times[0] + 3.0  # three seconds: small and quick to read
    rec = Recording(rec.times[keep], rec.acc[keep], rec.gyro[keep], rec.placements)
    generic = write_generic_csv(rec, work / "seed.csv", overwrite=True).read_bytes()
    phyphox = _phyphox(rec).encode()
    total, gyro = _sensor_logger(rec)
    meta = b"version,device name,recording time,platform\n3,fuzz,2024-01-01_00-00-00,android\n"
    sl_zip = _zip({"TotalAcceleration.csv": total, "Gyroscope.csv": gyro, "Metadata.csv": meta})
    models = []
    for name in ("mean", "ridge"):
        m = get_method(name).fit(db.subset([0, 1]), ["right_ankle"], "phone", 0)
        models.append({"model.npz": m.save(work / f"{name}.npz", overwrite=True).read_bytes()})
    asf, amc = _asf_amc()
    return {
        "bvh": [{"motion.bvh": bvh}],
        "asf": [{"skeleton.asf": asf.encode(), "motion.amc": amc.encode()}],
        "sensorlog": [{"log.csv": generic}, {"phyphox.csv": phyphox},
                      {"TotalAcceleration.csv": total}],
        "read_log": [{"log.csv": generic}, {"phyphox.csv": phyphox}, {"export.zip": sl_zip}],
        "model": models,
        "model_header": models + _shipped_model(),
        "real": real_seeds(),
        "xsens": xsens_seeds(rec.acc[:, 0], rec.gyro[:, 0]),
        "bvh-structure": [{"motion.bvh": bvh}],
        "amc-structure": [{"skeleton.asf": asf.encode(), "motion.amc": amc.encode()}],
        "zip-members": [{"export.zip": sl_zip}],
        "outputs": output_seeds(),
        "exports": export_seeds(rec.times, rec.acc[:, 0], rec.gyro[:, 0]),
        "live": live_seeds(rec.times, rec.acc[:, 0], rec.gyro[:, 0]),
    }


def _shipped_model() -> list[Files]:
    """The smallest shipped ``learned`` model (its header has the most parameters to
    forge); none without torch (the ``deep`` extra)."""
    if importlib.util.find_spec("torch") is None:
        return []
    path = min(Path(MODELS_DIR).glob("learned_*.npz"), key=lambda p: p.stat().st_size)
    return [{"model.npz": path.read_bytes()}]


def _cut_bvh(text: str, frames: int) -> str:
    head, motion = text.split("MOTION", 1)
    lines = motion.strip().splitlines()
    body = [ln for ln in lines[2:] if ln.strip()][:frames]
    return f"{head}MOTION\nFrames: {len(body)}\n{lines[1]}\n" + "\n".join(body) + "\n"


def _phyphox(rec) -> str:
    rows = [('"Time (s)","Acceleration x (m/s^2)","Acceleration y (m/s^2)",'
             '"Acceleration z (m/s^2)","Gyroscope x (rad/s)","Gyroscope y (rad/s)",'
             '"Gyroscope z (rad/s)"')]
    for t, a, g in zip(rec.times, rec.acc[:, 0], rec.gyro[:, 0]):
        rows.append(",".join(f"{v:.9g}" for v in (t, *a, *g)))
    return "\n".join(rows) + "\n"


def _sensor_logger(rec) -> tuple[bytes, bytes]:
    out = []
    for xyz in (rec.acc[:, 0], rec.gyro[:, 0]):
        rows = ["time,seconds_elapsed,z,y,x"]
        for t, (x, y, z) in zip(rec.times, xyz):
            rows.append(f"{1_700_000_000 * 10**9 + round(t * 1e9)},{t:.9f},{z:.9g},{y:.9g},"
                        f"{x:.9g}")
        out.append(("\n".join(rows) + "\n").encode())
    return out[0], out[1]


def _asf_amc(bones: int = 3, frames: int = 6) -> tuple[str, str]:
    """A root and a chain of ``bones`` bones (CMU conventions), and ``frames`` AMC frames."""
    names = [f"b{i}" for i in range(bones)]
    asf = [":version 1.10", ":name fuzz", ":units", "  mass 1.0", "  length 0.45",
           "  angle deg", ":root", "  order TX TY TZ RX RY RZ", "  axis XYZ",
           "  position 0 0 0", "  orientation 0 0 0", ":bonedata"]
    for i, n in enumerate(names):
        asf += ["  begin", f"    id {i + 1}", f"    name {n}", "    direction 0 -1 0",
                "    length 5", "    axis 0 0 0 XYZ", "    dof rx ry rz", "  end"]
    asf += [":hierarchy", "  begin", f"    root {names[0]}"]
    asf += [f"    {a} {b}" for a, b in itertools.pairwise(names)] + ["  end"]
    amc = [":FULLY-SPECIFIED", ":DEGREES"]
    for f in range(frames):
        amc += [str(f + 1), f"root 0 18 {f * 0.5:g} 0 {f * 3:g} 0"]
        amc += [f"{n} {f * 2:g} {-f:g} 0" for n in names]
    return "\n".join(asf) + "\n", "\n".join(amc) + "\n"


# ---------------------------------------------------------------------------------------------
# mutations

ATTACK_NUMBERS = ("1e308", "-1e308", "1e309", "nan", "inf", "-inf", "0", "-0", "1e-9", "1e-300",
                  "5e-324", "1e6", "1e7", "-1", "99999999999999999999999", "", "x", "0x10",
                  "1_000", "１２", "\x00", '"', "1,5", "1e", "--1", " ", "\t")


def _mutate_bytes(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    b = bytearray(data)
    op = rng.choice(("flip", "insert", "delete", "duplicate", "truncate", "zero"))
    if not b:  # truncated to nothing by an earlier step: only inserting changes it
        op = "insert"
    i = rng.randrange(len(b)) if b else 0
    n = rng.choice((1, 1, 2, 8, 64, 512))
    if op == "flip":
        for _ in range(n):
            b[rng.randrange(len(b))] = rng.randrange(256)
    elif op == "insert":
        b[i:i] = bytes(rng.randrange(256) for _ in range(n))
    elif op == "delete":
        del b[i:i + n]
    elif op == "duplicate":
        b[i:i] = b[i:i + n * 8]
    elif op == "truncate":
        del b[i:]
    else:
        b[i:i + n] = bytes(min(n, len(b) - i))
    return f"bytes:{op}", bytes(b)


def _mutate_lines(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    lines = data.split(b"\n")
    op = rng.choice(("delete", "duplicate", "swap", "repeat", "cell"))
    i, j = rng.randrange(len(lines)), rng.randrange(len(lines))
    if op == "delete":
        del lines[i]
    elif op == "duplicate":
        lines.insert(i, lines[j])
    elif op == "swap":
        lines[i], lines[j] = lines[j], lines[i]
    elif op == "repeat":
        lines[i:i] = [lines[i]] * rng.choice((2, 100, 5000))
    else:
        for _ in range(rng.choice((1, 1, 3, 20))):
            k = rng.randrange(len(lines))
            cells = lines[k].replace(b"\t", b" ").replace(b",", b" ").split(b" ")
            c = rng.randrange(len(cells))
            cells[c] = rng.choice(ATTACK_NUMBERS).encode()
            sep = b"," if b"," in lines[k] else b" "
            lines[k] = sep.join(cells)
    return f"lines:{op}", b"\n".join(lines)


def _table_attack(files: Files, rng: random.Random) -> tuple[str, Files]:
    """Structured attacks on a sensor-log table (the first file, or the members of a zip)."""
    name, data = next(iter(files.items()))
    if name.endswith(".zip"):
        with zipfile.ZipFile(io.BytesIO(data)) as z:
            members = {i.filename: z.read(i) for i in z.infolist()}
        target = rng.choice(sorted(members))
        kind, members[target] = _table_rows_attack(members[target], rng)
        op = rng.choice(("keep", "drop-metadata", "bomb-claim"))
        if op == "drop-metadata":
            members.pop("Metadata.csv", None)
        out = _zip(members)
        if op == "bomb-claim":
            out = _claim_size(out, target, 3 << 30)
        return f"attack:{kind}+{op}", {name: out}
    kind, out = _table_rows_attack(data, rng)
    return f"attack:{kind}", {name: out}


def _table_rows_attack(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    lines = data.decode("utf-8", "replace").splitlines()
    head, rows = lines[0], lines[1:]
    time_col = 0  # every seed table has its time first
    kind = rng.choice(("jump", "nanosecond", "huge-cell", "ms", "single", "nan", "binary",
                       "reverse", "constant-time", "short", "long-line", "repeat-rows"))

    def set_time(r: str, f: Callable[[float], float]) -> str:
        cells = r.split(",")
        cells[time_col] = repr(f(float(cells[time_col])))
        return ",".join(cells)

    if kind == "jump":
        k, jump = rng.randrange(len(rows)), rng.uniform(1e6, 1e7)
        scale = 1e9 if head.startswith("time,") else 1.0
        rows = rows[:k] + [set_time(r, lambda t: t + jump * scale) for r in rows[k:]]
    elif kind == "nanosecond":
        scale = 1.0 if head.startswith("time,") else 1e-9
        rows = [set_time(r, lambda t, i=i: i * scale) for i, r in enumerate(rows)]
    elif kind == "huge-cell":
        k = rng.randrange(len(rows))
        cells = rows[k].split(",")
        cells[rng.randrange(1, len(cells))] = rng.choice(("1e308", "-1e308", "1e300", "3e19"))
        rows[k] = ",".join(cells)
    elif kind == "ms":
        rows = [set_time(r, lambda t: t * 1e3) for r in rows]
    elif kind == "single":
        rows = rows[: rng.choice((0, 1, 2, 3))]
    elif kind == "nan":
        k = rng.randrange(len(rows))
        cells = rows[k].split(",")
        cells[rng.randrange(len(cells))] = rng.choice(("nan", "inf", "-inf", "NaN"))
        rows[k] = ",".join(cells)
    elif kind == "binary":
        k = rng.randrange(len(rows))
        return kind, ("\n".join([head, *rows[:k]]) + "\n").encode() + os.urandom(64) + \
            ("\n".join(rows[k:]) + "\n").encode()
    elif kind == "reverse":
        rows = rows[::-1]
    elif kind == "constant-time":
        rows = [set_time(r, lambda t: 5.0) for r in rows]
    elif kind == "short":
        rows = rows[: rng.choice((10, 30, 60))]
    elif kind == "long-line":
        rows.insert(rng.randrange(len(rows)), "1" * rng.choice((70_000, 1_000_000)))
    else:
        rows = rows * rng.choice((2, 5))
    return kind, ("\n".join([head, *rows]) + "\n").encode()


def _claim_size(data: bytes, member: str, size: int) -> bytes:
    """A zip whose central directory claims ``size`` uncompressed bytes for ``member``."""
    b = bytearray(data)
    sig, name = b"PK\x01\x02", member.encode()
    at = b.find(sig)
    while at >= 0:
        n = int.from_bytes(b[at + 28:at + 30], "little")
        if bytes(b[at + 46:at + 46 + n]) == name:
            b[at + 24:at + 28] = min(size, 0xFFFFFFFE).to_bytes(4, "little")
        at = b.find(sig, at + 46)
    return bytes(b)


def _bvh_attack(files: Files, rng: random.Random) -> tuple[str, Files]:
    text = next(iter(files.values())).decode()
    kind = rng.choice(("frame-time", "frames", "nested", "offset", "channels", "wide"))
    if kind == "frame-time":
        v = rng.choice(("0", "-1", "1000", "1e6", "1e-300", "nan", "inf", "0.0333", "5e-324"))
        text = "\n".join(f"Frame Time: {v}" if ln.startswith("Frame Time") else ln
                         for ln in text.splitlines())
    elif kind == "frames":
        v = rng.choice(("0", "-5", "1000000000", "41", "39", "1e3", "x"))
        text = "\n".join(f"Frames: {v}" if ln.startswith("Frames") else ln
                         for ln in text.splitlines())
    elif kind == "nested":
        depth = rng.choice((100, 2_000, 20_000))
        parts = ["HIERARCHY", "ROOT r", "{", "OFFSET 0 0 0",
                 "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"]
        for i in range(depth):
            parts += [f"JOINT j{i}", "{", "OFFSET 0 1 0", "CHANNELS 3 Zrotation Xrotation Yrotation"]
        parts += ["End Site", "{", "OFFSET 0 1 0", "}"] + ["}"] * (depth + 1)
        parts += ["MOTION", "Frames: 1", "Frame Time: 0.0333", " ".join(["0"] * (6 + 3 * depth))]
        text = "\n".join(parts)
    elif kind == "offset":
        text = text.replace("OFFSET", f"OFFSET {rng.choice(ATTACK_NUMBERS[:12])}", 1)
    elif kind == "channels":
        text = text.replace("CHANNELS 3", f"CHANNELS {rng.choice(('0', '-3', '1000000', '4'))}", 1)
    else:
        lines = text.splitlines()
        k = rng.randrange(len(lines) - 3, len(lines))
        lines[k] = lines[k] + " 0" * rng.choice((1, 3, 100000))
        text = "\n".join(lines)
    return f"attack:{kind}", {next(iter(files)): text.encode()}


def _asf_attack(files: Files, rng: random.Random) -> tuple[str, Files]:
    names = list(files)
    asf, amc = (files[n].decode() for n in names)
    kind = rng.choice(("units", "nested", "dof", "amc-values", "amc-frames", "cycle"))
    if kind == "units":
        v = rng.choice(("5e-324", "0", "-1", "nan", "inf", "1e308", "x"))
        asf = asf.replace("length 0.45", f"length {v}")
    elif kind == "nested":
        asf, amc = _asf_amc(bones=rng.choice((100, 2_000, 20_000)), frames=2)
    elif kind == "dof":
        asf = asf.replace("dof rx ry rz", rng.choice(("dof rx rx", "dof", "dof qq", "dof rx ry rz l")),
                          1)
    elif kind == "amc-values":
        lines = amc.splitlines()
        k = rng.randrange(2, len(lines))
        cells = lines[k].split(" ")
        cells[rng.randrange(len(cells))] = rng.choice(ATTACK_NUMBERS[:14])
        lines[k] = " ".join(cells)
        amc = "\n".join(lines)
    elif kind == "amc-frames":
        amc = amc.replace("\n3\n", rng.choice(("\n99999999\n", "\n-1\n", "\n2\n", "\nx\n")), 1)
    else:
        asf = asf.replace("    b1 b2", "    b1 b2\n    b2 b0", 1)
    return f"attack:{kind}", {names[0]: asf.encode(), names[1]: amc.encode()}


def _model_attack(files: Files, rng: random.Random) -> tuple[str, Files]:
    name, data = next(iter(files.items()))
    with zipfile.ZipFile(io.BytesIO(data)) as z:
        members = {i.filename: z.read(i) for i in z.infolist()}
    header = json.loads(np.lib.format.read_array(io.BytesIO(members["__header__.npy"])).tobytes())
    kind = rng.choice(("fps", "placements", "params", "noise", "deep", "header-type", "shape",
                       "reshape", "bomb-claim", "nan-weights", "object", "drop"))
    if kind in ("fps", "placements", "params", "noise", "header-type"):
        values = {"fps": (-1, 0, 1e308, "30", None, True, 1e-9, 30.0),
                  "placements": ([], "nose", ["nose"], [1], ["right_ankle"] * 2, None),
                  "params": ([1], None, "x", {"nope": 1}, {}),
                  "noise": ("loud", None, 1, "phone"),
                  "header-type": ([1, 2], "x", 3, None)}[kind]
        v = rng.choice(values)
        if kind == "header-type":
            header = v
        else:
            header[kind] = v
        members["__header__.npy"] = _npy(np.frombuffer(json.dumps(header).encode(), np.uint8))
    elif kind == "deep":
        depth = rng.choice((40, 1_000, 100_000))
        text = json.dumps(header).replace('"protocol": {',
                                          '"protocol": {"x": ' + "[" * depth + "]" * depth + ",")
        members["__header__.npy"] = _npy(np.frombuffer(text.encode(), np.uint8))
    elif kind == "shape":
        target = rng.choice([m for m in members if m != "__header__.npy"])
        buf = io.BytesIO()
        np.lib.format.write_array_header_1_0(buf, {"descr": "<f8", "fortran_order": False,
                                                   "shape": (10**6, 10**7)})
        members[target] = buf.getvalue() + b"\0" * 32
    elif kind in ("reshape", "nan-weights", "object"):
        target = rng.choice([m for m in members if m != "__header__.npy"])
        arr = np.lib.format.read_array(io.BytesIO(members[target]))
        if kind == "reshape":
            arr = arr.reshape(-1)[: max(1, arr.size // 2)]
        elif kind == "nan-weights" and arr.dtype.kind == "f":
            arr = arr.copy()
            arr.reshape(-1)[rng.randrange(arr.size)] = rng.choice((np.nan, np.inf))
        elif kind == "object":
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.array([{"a": 1}], dtype=object), allow_pickle=True)
            members[target] = buf.getvalue()
            arr = None
        if arr is not None:
            members[target] = _npy(arr)
    elif kind == "drop":
        members.pop(rng.choice(sorted(members)))
    out = _zip(members)
    if kind == "bomb-claim":
        out = _claim_size(out, rng.choice(sorted(members)), rng.choice((3 << 30, 1 << 31)))
    return f"attack:{kind}", {name: out}


# values a forged header field may take: huge and non-finite numbers, other types, nesting
HEADER_VALUES = (10**6, 10**9, 10**18, 10**400, -1, 0, 1e7, 1e308, -1e308, float("nan"),
                 float("inf"), float("-inf"), 2.5, True, False, None, "x", "", [], [1, 2],
                 {}, {"a": 1})


def _header_attack(files: Files, rng: random.Random) -> tuple[str, Files]:
    """One value anywhere in a model's JSON header (a parameter, a learned value, the
    protocol, a top-level field) replaced by one of :data:`HEADER_VALUES` or a deep nest."""
    name, data = next(iter(files.items()))
    with zipfile.ZipFile(io.BytesIO(data)) as z:
        members = {i.filename: z.read(i) for i in z.infolist()}
    header = json.loads(np.lib.format.read_array(io.BytesIO(members["__header__.npy"])).tobytes())
    paths = [(k,) for k in header] + [(k, sub) for k in ("params", "values", "protocol")
                                      if isinstance(header.get(k), dict) for sub in header[k]]
    path = rng.choice(paths)
    if rng.random() < 0.1:
        depth = rng.choice((10, 40, 10_000))
        value: object = "NEST"
        label = f"nest{depth}"
    else:
        value = rng.choice(HEADER_VALUES)
        label = repr(value)[:12]
    target = header
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = value
    text = json.dumps(header)  # NaN and Infinity as Python's json writes them
    if value == "NEST":
        text = text.replace('"NEST"', "[" * depth + "]" * depth)
    members["__header__.npy"] = _npy(np.frombuffer(text.encode(), np.uint8))
    return f"header:{'.'.join(path)}={label}", {name: _zip(members)}


def _npy(arr: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, arr, allow_pickle=False)
    return buf.getvalue()


ATTACKS = {"bvh": _bvh_attack, "asf": _asf_attack, "sensorlog": _table_attack,
           "read_log": _table_attack, "model": _model_attack, "model_header": _header_attack,
           "real": real_attack, "xsens": xsens_attack, "bvh-structure": bvh_structure_attack,
           "amc-structure": amc_structure_attack, "zip-members": zip_member_attack,
           "outputs": output_attack, "exports": export_attack, "live": live_attack}


ONLY_ATTACKS = ("model_header",)  # structure-aware only: a flipped byte is the "model" class


def cases(reader: str, seeds: list[Files], n: int, seed: int = 0) -> Iterator[Case]:
    """``n`` inputs for ``reader``: a third structured attacks, the rest random mutations
    (1-3 of bytes or lines) of a seed file."""
    rng = random.Random(f"{reader}-{seed}")
    for _ in range(n):
        files = dict(rng.choice(seeds))
        if reader in ONLY_ATTACKS or reader in STRUCTURED or rng.random() < 1 / 3:
            mutation, files = ATTACKS[reader](files, rng)
        else:
            target = rng.choice(list(files))
            steps = []
            for _ in range(rng.choice((1, 1, 2, 3))):
                op = _mutate_bytes if rng.random() < 0.5 else _mutate_lines
                step, files[target] = op(files[target], rng)
                steps.append(step)
            mutation = "+".join(steps)
        yield Case(reader, mutation, tuple(files.items()))


# ---------------------------------------------------------------------------------------------
# reading one input and judging the result (in the worker)

def read_case(reader: str, paths: list[Path]) -> object:
    """Read ``paths`` as ``reader`` does; returns what was read."""
    reader = STRUCTURED.get(reader, reader)
    if reader == "outputs":
        return write_outputs(paths[0])
    if reader == "bvh":
        return read_bvh(paths[0])
    if reader == "asf":
        return read_asf_amc(paths[0], paths[1])
    if reader == "sensorlog":
        name = paths[0].name
        if name == "TotalAcceleration.csv":
            (paths[0].parent / "Gyroscope.csv").write_bytes(paths[0].read_bytes())
            return read_sensor_logger(paths[0].parent, "android")
        return (read_phyphox if name.startswith("phyphox") else read_generic_csv)(paths[0])
    if reader in ("read_log", "xsens"):
        return read_log(paths[0])
    if reader == "real":
        return read_real(paths)
    if reader == "exports":
        return read_export(paths)
    if reader == "live":
        return play(paths)
    return load_model(paths[0])


def garbage(reader: str, result: object) -> str | None:
    """Why an accepted ``result`` is implausible, or ``None`` (see the module docstring)."""
    reader = STRUCTURED.get(reader, reader)
    if reader == "outputs":
        return output_garbage(result)
    if reader in ("bvh", "asf"):
        m = result
        if not (1.0 <= m.fps <= 1000.0):
            return f"fps {m.fps}"
        if m.num_frames < 1:
            return "no frames"
        for name in ("rotations", "root"):
            if not np.isfinite(getattr(m, name)).all():
                return f"non-finite {name}"
        if not np.isfinite(m.skeleton.offsets).all():
            return "non-finite offsets"
        return None
    if reader == "sensorlog":
        for s in result:
            if not (np.isfinite(s.times).all() and np.isfinite(s.values).all()):
                return "non-finite stream"
            if len(s.times) < 1:
                return "empty stream"
        return None
    if reader in ("read_log", "xsens"):
        rec, report = result
        if not np.isfinite(rec.channels()).all() or not np.isfinite(rec.times).all():
            return "non-finite recording"
        if rec.num_samples < 2 or not rec.is_uniform():
            return "not a uniform recording"
        if abs(rec.times[-1] - report.duration) > 0.05 or report.duration > 48 * 3600:
            return f"duration {report.duration} against {rec.times[-1]}"
        return None
    if reader == "real":
        return real_garbage(result)
    if reader == "exports":
        return export_garbage(result)
    if reader == "live":
        return live_garbage(result)
    model = result
    if reader == "model_header":  # the forged value got past the header's checks
        try:
            model.check_params()
        except ImulocoError as e:
            return f"params: {e}"
        at = non_finite(model.get_state()[1])
        if at is not None:
            return f"non-finite learned value {at}"
    try:
        check_header("model", {"format_version": 1, "method": model.name,
                               "params": model.get_params(), "values": {}, "protocol": {},
                               "skeleton": {"names": model.skeleton_.names, "body_map": {},
                                            "end_sites": {}},
                               "placements": model.placements_, "noise": model.noise_,
                               "fps": model.fps_})
    except Exception as e:  # noqa: BLE001 - any failure is the verdict
        return f"header: {e}"
    signals = np.zeros((40, 6 * len(model.placements_)))
    signals[:, 1] = 9.81
    try:
        motion = model.reconstruct_signals(signals)
    except Exception as e:  # noqa: BLE001 - a model that loads but cannot reconstruct
        return f"reconstruct: {type(e).__name__}: {e}"
    if not (np.isfinite(motion.rotations).all() and np.isfinite(motion.root).all()):
        return "non-finite reconstruction"
    return None


def judge(reader: str, paths: list[Path]) -> tuple[str, str]:
    """(outcome, detail) of reading ``paths`` (in the calling process, no time limit)."""
    logging.disable(logging.CRITICAL)
    warnings.simplefilter("ignore")
    try:
        result = read_case(reader, paths)
    except ImulocoError as e:
        named = any(p.name in str(e) for p in paths) or str(paths[0].parent) in str(e)
        return ("clean" if named else "wrong exception type"), f"{type(e).__name__}: {e}"[:200]
    except Exception as e:  # noqa: BLE001 - counting foreign exceptions is the point
        return "wrong exception type", f"{type(e).__name__}: {e}"[:200]
    except RecursionError as e:
        return "wrong exception type", f"RecursionError: {e}"[:200]
    why = garbage(reader, result)
    return ("accepted", "") if why is None else ("garbage accepted", why)


def _worker(conn) -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))
    while True:
        job = conn.recv()
        if job is None:
            return
        reader, paths = job
        try:
            conn.send(judge(reader, [Path(p) for p in paths]))
        except BaseException as e:  # noqa: BLE001 - MemoryError while judging, ...
            conn.send(("wrong exception type", f"{type(e).__name__}: {e}"[:200]))


class _Pool:
    """One worker process; a job without an answer in ``timeout`` s kills and replaces it."""

    def __init__(self, timeout: float) -> None:
        self.timeout = timeout
        self._ctx = mp.get_context("fork")
        self._start()

    def _start(self) -> None:
        self._conn, child = self._ctx.Pipe()
        self._proc = self._ctx.Process(target=_worker, args=(child,), daemon=True)
        self._proc.start()
        child.close()

    def run(self, reader: str, paths: list[Path]) -> tuple[str, str, float]:
        t0 = time.perf_counter()
        self._conn.send((reader, [str(p) for p in paths]))
        if self._conn.poll(self.timeout):
            try:
                outcome, detail = self._conn.recv()
                return outcome, detail, time.perf_counter() - t0
            except EOFError:  # the worker died (killed by the kernel, a crash)
                self._restart()
                return "wrong exception type", "worker died", time.perf_counter() - t0
        self._restart()
        return "hang", f"no answer in {self.timeout:g} s", time.perf_counter() - t0

    def _restart(self) -> None:
        self._proc.kill()
        self._proc.join()
        self._conn.close()
        self._start()

    def close(self) -> None:
        try:
            self._conn.send(None)
        except OSError:
            pass
        self._proc.join(5)
        if self._proc.is_alive():
            self._proc.kill()
            self._proc.join()


def run_fuzz(n: int, readers: tuple[str, ...] = READERS, timeout: float = 5.0, seed: int = 0,
             progress: bool = False, examples: int = 3) -> dict[str, dict]:
    """Read ``n`` generated inputs per reader; per reader the count of each outcome, the
    slowest input's seconds and up to ``examples`` examples of each outcome but ``accepted``."""
    results: dict[str, dict] = {}
    with tempfile.TemporaryDirectory(prefix="imuloco-fuzz-") as tmp:
        work = Path(tmp)
        seeds = seed_files(work)
        if "model_header" in readers and importlib.util.find_spec("torch"):  # torch (the deep extra) imported
            # before the workers fork: importing it in each took 8 s of a case's time limit
            method_class("learned")
        if "live" in readers:
            live_method()  # fitted once, before the fork
        pool = _Pool(timeout)
        try:
            for reader in readers:
                counts: Counter = Counter()
                found: dict[str, list[str]] = {}
                slowest = 0.0
                for i, case in enumerate(tqdm(cases(reader, seeds[reader], n, seed), total=n,
                                              desc=f"fuzz {reader}", disable=not progress)):
                    folder = work / f"{reader}-{i}"
                    folder.mkdir()
                    paths = []
                    for name, data in case.files:  # a name may hold "/" (real-data trees)
                        (folder / name).parent.mkdir(parents=True, exist_ok=True)
                        (folder / name).write_bytes(data)
                        paths.append(folder / name)
                    outcome, detail, seconds = pool.run(reader, paths)
                    slowest = max(slowest, seconds)
                    counts[outcome] += 1
                    if outcome != "accepted" and len(found.setdefault(outcome, [])) < examples:
                        found[outcome].append(f"{case.mutation}: {detail}")
                    shutil.rmtree(folder)
                results[reader] = {"inputs": n, **{o: counts[o] for o in OUTCOMES},
                                   "slowest_s": round(slowest, 2), "examples": found}
        finally:
            pool.close()
    return results


def table(results: dict[str, dict]) -> str:
    """The issue's table (Markdown) of :func:`run_fuzz`'s results."""
    rows = ["| reader | inputs | " + " | ".join(OUTCOMES) + " | slowest (s) |",
            "|---|" + "---|" * (len(OUTCOMES) + 2)]
    for reader, r in results.items():
        rows.append(f"| {READER_TITLES[reader]} | {r['inputs']:,} | "
                    + " | ".join(f"{r[o]:,}" for o in OUTCOMES) + f" | {r['slowest_s']} |")
    return "\n".join(rows)


def write_fuzz(n: int, out: str | Path, readers: tuple[str, ...] = READERS, timeout: float = 5.0,
               seed: int = 0, progress: bool = False) -> str:
    """Run :func:`run_fuzz` and write ``fuzz.json`` and ``fuzz.md`` (the table, the conditions
    and examples of every outcome but ``accepted``) into ``out``; returns the table."""
    t0 = time.perf_counter()
    results = run_fuzz(n, readers, timeout, seed, progress)
    seconds = time.perf_counter() - t0
    out = Path(out)
    conditions = (f"{n:,} inputs per reader, seed {seed}, {timeout:g} s per input, "
                  f"{MEMORY_LIMIT >> 30} GiB address space per worker; {seconds:.0f} s on "
                  f"{host.machine()}, {os.cpu_count()} CPUs")
    with atomic_write(out / "fuzz.json", "w") as f:
        json.dump({"conditions": conditions, "results": results}, f, indent=2)
    lines = ["# Reader fuzzing (`imuloco bench --fuzz`)", "", conditions, "", table(results), ""]
    for reader, r in results.items():
        for outcome, found in r["examples"].items():
            lines.append(f"- {READER_TITLES[reader]}, {outcome}:")
            lines += [f"  - `{e}`" for e in found]
    with atomic_write(out / "fuzz.md", "w") as f:
        f.write("\n".join(lines) + "\n")
    return table(results) + f"\n{conditions}\nwrote {out / 'fuzz.md'} and {out / 'fuzz.json'}"
