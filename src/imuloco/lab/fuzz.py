"""Fuzzing the readers: generated malformed inputs, each read with a time limit.

``imuloco bench --fuzz N`` runs :func:`run_fuzz`: for each reader (BVH, ASF/AMC, sensor-log
tables, :func:`~imuloco.sensors.reallog.read_log`, model files, the real-data folders of
:func:`~imuloco.io.realimu.read_trials`: :mod:`imuloco.lab.fuzz_real`, Xsens text exports
read by ``read_log``: :mod:`imuloco.lab.fuzz_xsens`, a second sensor (a Sensor Logger
export's watch, ``--sensor`` files on clocks of their own): :mod:`imuloco.lab.fuzz_watch`;
one row each in :data:`READER_TABLE`) it builds small valid files from the bundled sample (:func:`seed_files`), derives N inputs from
them by random edits (bytes, lines, cells: :mod:`imuloco.lab.mutations`, the engine the
readers' tests use too) and by the structured attacks of issue 18 (a timestamp jumping by days,
rows a nanosecond apart, cells of 1e308, ``Frame Time`` of 1000 s, 20,000 nested joints, ASF units of
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
from imuloco.lab.fuzz_exports import export_attack, export_garbage, export_seeds, read_export
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
from imuloco.lab.fuzz_watch import read_watch, watch_attack, watch_garbage, watch_seeds
from imuloco.lab.fuzz_xsens import xsens_attack, xsens_seeds
from imuloco.lab.mutations import ATTACK_NUMBERS, Files, claim_size, mutate, npy, unzip, zip_files
from imuloco.methods import get_method, load_model, method_class
from imuloco.methods.modelfile import check_header, non_finite
from imuloco.sensors.reallog import read_log
from imuloco.sensors.simulate import simulate

OUTCOMES = ("clean", "accepted", "wrong exception type", "hang", "garbage accepted")
MEMORY_LIMIT = 4 << 30  # bytes of address space per worker


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
    sl_zip = zip_files({"TotalAcceleration.csv": total, "Gyroscope.csv": gyro, "Metadata.csv": meta})
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
        "watch": watch_seeds(clip, work),
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
# structured attacks (the random edits are the engine's: imuloco.lab.mutations)

def _table_attack(files: Files, rng: random.Random) -> tuple[str, Files]:
    """Structured attacks on a sensor-log table (the first file, or the members of a zip)."""
    name, data = next(iter(files.items()))
    if name.endswith(".zip"):
        members = unzip(data)
        target = rng.choice(sorted(members))
        kind, members[target] = _table_rows_attack(members[target], rng)
        op = rng.choice(("keep", "drop-metadata", "bomb-claim"))
        if op == "drop-metadata":
            members.pop("Metadata.csv", None)
        out = zip_files(members)
        if op == "bomb-claim":
            out = claim_size(out, target, 3 << 30)
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
    members = unzip(data)
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
        members["__header__.npy"] = npy(np.frombuffer(json.dumps(header).encode(), np.uint8))
    elif kind == "deep":
        depth = rng.choice((40, 1_000, 100_000))
        text = json.dumps(header).replace('"protocol": {',
                                          '"protocol": {"x": ' + "[" * depth + "]" * depth + ",")
        members["__header__.npy"] = npy(np.frombuffer(text.encode(), np.uint8))
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
            members[target] = npy(arr)
    elif kind == "drop":
        members.pop(rng.choice(sorted(members)))
    out = zip_files(members)
    if kind == "bomb-claim":
        out = claim_size(out, rng.choice(sorted(members)), rng.choice((3 << 30, 1 << 31)))
    return f"attack:{kind}", {name: out}


# values a forged header field may take: huge and non-finite numbers, other types, nesting
HEADER_VALUES = (10**6, 10**9, 10**18, 10**400, -1, 0, 1e7, 1e308, -1e308, float("nan"),
                 float("inf"), float("-inf"), 2.5, True, False, None, "x", "", [], [1, 2],
                 {}, {"a": 1})


def _header_attack(files: Files, rng: random.Random) -> tuple[str, Files]:
    """One value anywhere in a model's JSON header (a parameter, a learned value, the
    protocol, a top-level field) replaced by one of :data:`HEADER_VALUES` or a deep nest."""
    name, data = next(iter(files.items()))
    members = unzip(data)
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
    members["__header__.npy"] = npy(np.frombuffer(text.encode(), np.uint8))
    return f"header:{'.'.join(path)}={label}", {name: zip_files(members)}


# ---------------------------------------------------------------------------------------------
# reading one input and judging the result (in the worker)

def _read_table(paths: list[Path]) -> list:
    """A sensor-log table as its own reader reads it (by the seed's name)."""
    name = paths[0].name
    if name == "TotalAcceleration.csv":
        (paths[0].parent / "Gyroscope.csv").write_bytes(paths[0].read_bytes())
        return read_sensor_logger(paths[0].parent, "android")
    return (read_phyphox if name.startswith("phyphox") else read_generic_csv)(paths[0])


def _motion_garbage(m) -> str | None:
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


def _streams_garbage(streams) -> str | None:
    for s in streams:
        if not (np.isfinite(s.times).all() and np.isfinite(s.values).all()):
            return "non-finite stream"
        if len(s.times) < 1:
            return "empty stream"
    return None


def _log_garbage(result) -> str | None:
    rec, report = result
    if not np.isfinite(rec.channels()).all() or not np.isfinite(rec.times).all():
        return "non-finite recording"
    if rec.num_samples < 2 or not rec.is_uniform():
        return "not a uniform recording"
    if abs(rec.times[-1] - report.duration) > 0.05 or report.duration > 48 * 3600:
        return f"duration {report.duration} against {rec.times[-1]}"
    return None


def _model_garbage(model) -> str | None:
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


def _header_garbage(model) -> str | None:
    """A forged header value that got past the header's checks, or :func:`_model_garbage`."""
    try:
        model.check_params()
    except ImulocoError as e:
        return f"params: {e}"
    at = non_finite(model.get_state()[1])
    if at is not None:
        return f"non-finite learned value {at}"
    return _model_garbage(model)


@dataclass(frozen=True)
class Reader:
    """One row of the fuzzer's table: a reader (or an attack class read as one)."""

    title: str  # its row in fuzz.md's table
    read: Callable[[list[Path]], object]  # the case's files -> what was read
    garbage: Callable[[object], str | None]  # why an accepted result is implausible, or None
    attack: Callable[[Files, random.Random], tuple[str, Files]]  # one structured attack
    edits: bool = True  # a third of its inputs attacks, the rest random edits; False: all attacks


def _first(read: Callable) -> Callable[[list[Path]], object]:
    return lambda paths: read(paths[0])


_read_bvh, _read_log, _read_model = _first(read_bvh), _first(read_log), _first(load_model)


def _read_asf(paths: list[Path]) -> object:
    return read_asf_amc(paths[0], paths[1])


# the readers in their order in fuzz.md; issue 42's classes (lab/fuzz_structure.py) are read as
# the reader they stand for, every input an attack (model headers: a flipped byte is "model")
READER_TABLE = {
    "bvh": Reader("BVH", _read_bvh, _motion_garbage, _bvh_attack),
    "asf": Reader("ASF/AMC", _read_asf, _motion_garbage, _asf_attack),
    "sensorlog": Reader("sensor-log tables", _read_table, _streams_garbage, _table_attack),
    "read_log": Reader("`read_log`", _read_log, _log_garbage, _table_attack),
    "model": Reader("model files", _read_model, _model_garbage, _model_attack),
    "model_header": Reader("model headers (JSON values)", _read_model, _header_garbage,
                           _header_attack, edits=False),
    "real": Reader("real-data folders (`read_trials`)", read_real, real_garbage, real_attack),
    "xsens": Reader("Xsens exports (`read_log`)", _read_log, _log_garbage, xsens_attack),
    "bvh-structure": Reader("BVH, structure-aware", _read_bvh, _motion_garbage,
                            bvh_structure_attack, edits=False),
    "amc-structure": Reader("AMC, structure-aware", _read_asf, _motion_garbage,
                            amc_structure_attack, edits=False),
    "zip-members": Reader("zip members (`read_log`)", _read_log, _log_garbage,
                          zip_member_attack, edits=False),
    "outputs": Reader("output targets (`check_outputs`, `OutputSet`)", _first(write_outputs),
                      output_garbage, output_attack, edits=False),
    "exports": Reader("phone exports: units, zip folders, links (`read_log`)", read_export,
                      export_garbage, export_attack),
    "live": Reader("live server messages and requests (loopback)", play, live_garbage,
                   live_attack),
    "watch": Reader("a second sensor: Sensor Logger's watch, `--sensor` clocks (`read_sensors`)",
                    read_watch, watch_garbage, watch_attack),
}
READERS = tuple(READER_TABLE)
READER_TITLES = {name: r.title for name, r in READER_TABLE.items()}
ATTACKS = {name: r.attack for name, r in READER_TABLE.items()}


def cases(reader: str, seeds: list[Files], n: int, seed: int = 0) -> Iterator[Case]:
    """``n`` inputs for ``reader``: a third structured attacks, the rest 1-3 random edits of
    bytes or lines (:func:`imuloco.lab.mutations.mutate`) of a seed file."""
    rng = random.Random(f"{reader}-{seed}")
    row = READER_TABLE[reader]
    for _ in range(n):
        files = dict(rng.choice(seeds))
        if not row.edits or rng.random() < 1 / 3:
            mutation, files = row.attack(files, rng)
        else:
            target = rng.choice(list(files))
            mutation, files[target] = mutate(files[target], rng, rng.choice((1, 1, 2, 3)))
        yield Case(reader, mutation, tuple(files.items()))


def judge(reader: str, paths: list[Path]) -> tuple[str, str]:
    """(outcome, detail) of reading ``paths`` (in the calling process, no time limit)."""
    logging.disable(logging.CRITICAL)
    warnings.simplefilter("ignore")
    try:
        result = READER_TABLE[reader].read(paths)
    except ImulocoError as e:
        named = any(p.name in str(e) for p in paths) or str(paths[0].parent) in str(e)
        return ("clean" if named else "wrong exception type"), f"{type(e).__name__}: {e}"[:200]
    except Exception as e:  # noqa: BLE001 - counting foreign exceptions is the point
        return "wrong exception type", f"{type(e).__name__}: {e}"[:200]
    except RecursionError as e:
        return "wrong exception type", f"RecursionError: {e}"[:200]
    why = READER_TABLE[reader].garbage(result)
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
