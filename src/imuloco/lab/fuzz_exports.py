"""The ``exports`` reader kind of ``imuloco bench --fuzz`` (issue 42, items 11, 12, 15): what a
phone export says of itself, read with :func:`~imuloco.sensors.reallog.read_log`.

Seeds (:func:`export_seeds`) are one walk as a phyphox table (acceleration and gyroscope, one
time column), a Sensor Logger zip (its tables in one folder) and a Sensor Logger folder beside
a file outside it. The structured attacks (:func:`export_attack`):

* ``units``: each signal column of the phyphox table gets its own unit (m/s^2, m/s², g; rad/s,
  deg/s), its values written in it, so the file is truthful column by column;
* ``folders``: the zip's members spread over folders (``a/``, ``b/``, ``meta/``, ``__MACOSX/``,
  the root), as two phones' exports zipped together are;
* ``links``: a table of the folder replaced by a link: out of the folder to a valid table or to
  a file of secrets (``root:x:0:0:...``), within the folder, dangling, or a loop.

:func:`read_export` judges what the readers may not do: read a link out of the folder, read
tables of several folders as one recording, or quote more than an excerpt of another file in an
error; :func:`export_garbage` adds that an accepted walk must look like one (median |acc| 6-14
m/s^2, 99th percentile of |gyro| 0.5-30 rad/s: a column read in the wrong unit is 9.8 or 57 times
off).
"""

from __future__ import annotations

import json
import os
import random
from pathlib import Path

import numpy as np

from imuloco.errors import EXCERPT_CHARS, ImulocoError
from imuloco.lab.mutations import Files, unzip, zip_files
from imuloco.sensors.reallog import read_log

SECRET = "root:x:0:0:root:/root:/bin/bash"  # another file's line no error may quote
ACC_UNITS = {"m/s^2": 1.0, "m/s²": 1.0, "g": 1 / 9.80665}  # file value per m/s^2
GYRO_UNITS = {"rad/s": 1.0, "deg/s": 180 / np.pi}  # file value per rad/s
KINDS = ("units", "folders", "links")
LINKS = "links.json"  # the layout file of a folder case: member -> link target
META = b"version,device name,recording time,platform\n3,fuzz,2024-01-01_00-00-00,android\n"


def export_seeds(times: np.ndarray, acc: np.ndarray, gyro: np.ndarray) -> list[Files]:
    """The three seeds of a walk: times (N,) s, acc (N, 3) m/s^2, gyro (N, 3) rad/s."""
    total, gyr = _sensor_logger(times, acc), _sensor_logger(times, gyro)
    zipped = zip_files({"Walk/TotalAcceleration.csv": total, "Walk/Gyroscope.csv": gyr,
                   "Walk/Metadata.csv": META})
    folder = {LINKS: b"{}", "export/TotalAcceleration.csv": total,
              "export/Gyroscope.csv": gyr, "export/Metadata.csv": META,
              "outside.csv": gyr, "secret.txt": (SECRET + "\n") * 3}
    return [{"phyphox.csv": _phyphox(times, acc, gyro, ("m/s^2",) * 3, ("rad/s",) * 3)},
            {"export.zip": zipped}, {k: v if isinstance(v, bytes) else v.encode()
                                     for k, v in folder.items()}]


def _phyphox(times: np.ndarray, acc: np.ndarray, gyro: np.ndarray, acc_units: tuple[str, ...],
             gyro_units: tuple[str, ...]) -> bytes:
    head = ['"Time (s)"'] + [f'"Acceleration {a} ({u})"' for a, u in zip("xyz", acc_units)] \
        + [f'"Gyroscope {a} ({u})"' for a, u in zip("xyz", gyro_units)]
    scale = np.array([ACC_UNITS[u] for u in acc_units] + [GYRO_UNITS[u] for u in gyro_units])
    rows = [",".join(f"{v:.9g}" for v in (t, *values))
            for t, values in zip(times, np.c_[acc, gyro] * scale)]
    return (",".join(head) + "\n" + "\n".join(rows) + "\n").encode()


def _sensor_logger(times: np.ndarray, xyz: np.ndarray) -> bytes:
    rows = ["time,seconds_elapsed,z,y,x"]
    rows += [f"{1_700_000_000 * 10**9 + round(t * 1e9)},{t:.9f},{z:.9g},{y:.9g},{x:.9g}"
             for t, (x, y, z) in zip(times, xyz)]
    return ("\n".join(rows) + "\n").encode()


def export_attack(files: Files, rng: random.Random) -> tuple[str, Files]:
    """One structured attack (module docstring) on a seed, by the seed's kind."""
    name = next(iter(files))
    if name == "phyphox.csv":
        return _units_attack(files[name], rng)
    if name == "export.zip":
        return _folders_attack(files[name], rng)
    return _links_attack(dict(files), rng)


def _units_attack(data: bytes, rng: random.Random) -> tuple[str, Files]:
    lines = data.decode().splitlines()
    table = np.array([[float(c) for c in ln.split(",")] for ln in lines[1:]])
    same = rng.random() < 0.5
    acc_u = (rng.choice(list(ACC_UNITS)),) * 3 if same else tuple(
        rng.choice(list(ACC_UNITS)) for _ in range(3))
    gyro_u = (rng.choice(list(GYRO_UNITS)),) * 3 if same else tuple(
        rng.choice(list(GYRO_UNITS)) for _ in range(3))
    out = _phyphox(table[:, 0], table[:, 1:4], table[:, 4:7], acc_u, gyro_u)
    mixed = len({ACC_UNITS[u] for u in acc_u}) > 1 or len(set(gyro_u)) > 1
    return f"attack:units-{'mixed' if mixed else 'one'}", {"phyphox.csv": out}


def _folders_attack(data: bytes, rng: random.Random) -> tuple[str, Files]:
    members = {k.rsplit("/", 1)[-1]: v for k, v in unzip(data).items()}
    places = ("", "a/", "b/", "Walk/", "a/meta/", "__MACOSX/", "a/b/")
    placed = {rng.choice(places) + n: d for n, d in members.items()}
    if rng.random() < 0.3:  # the same table twice, in two folders (two phones)
        placed[rng.choice(places[1:4]) + "Gyroscope.csv"] = members["Gyroscope.csv"]
    folders = sorted({k.rpartition("/")[0] or "." for k in placed})
    return f"attack:folders-{'+'.join(folders)}", {"export.zip": zip_files(placed)}


def _links_attack(files: Files, rng: random.Random) -> tuple[str, Files]:
    member = rng.choice(("Gyroscope.csv", "TotalAcceleration.csv", "Metadata.csv"))
    kind, target = rng.choice((("out-valid", "../outside.csv"), ("out-secret", "../secret.txt"),
                               ("absolute-secret", "SECRET"), ("inside", "renamed.csv"),
                               ("dangling", "nowhere.csv"), ("loop", member)))
    if kind == "inside":
        files[f"export/{target}"] = files[f"export/{member}"]
    files[LINKS] = json.dumps({f"export/{member}": target}).encode()
    return f"attack:link-{kind}-{member}", files


def read_export(paths: list[Path]) -> dict:
    """Read a case as ``reconstruct`` does: ``{"result": (recording, report) or None,
    "problem": why the reading was wrong or None}``; the library's refusals are raised."""
    first = paths[0]
    target, problem = first, None
    if first.name == LINKS:
        target, problem = _make_links(first)
    try:
        result = read_log(target, rate=None)
    except ImulocoError as e:
        if SECRET[:EXCERPT_CHARS + 1] in str(e):
            return {"result": None, "problem": f"the error quotes another file: {e}"[:200]}
        raise
    if first.name == "export.zip":
        problem = _folders_problem(first, result[1])
    return {"result": result, "problem": problem}


def _make_links(layout: Path) -> tuple[Path, str | None]:
    """Turn the members ``layout`` names into links (``SECRET``: the secret file's absolute
    path); the export folder, and what accepting it would mean when a link leads out."""
    root = layout.parent
    try:
        links = json.loads(layout.read_text("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        links = {}
    out = None
    for member, target in (links.items() if isinstance(links, dict) else ()):
        path = root / str(member)
        if not isinstance(target, str) or not path.resolve().is_relative_to(root.resolve()):
            continue
        path.unlink(missing_ok=True)
        path.parent.mkdir(parents=True, exist_ok=True)
        target = str(root / "secret.txt") if target == "SECRET" else target
        path.symlink_to(target)
        lands = Path(os.path.normpath(path.parent / target))  # a loop is not resolved
        if not lands.is_relative_to(path.parent):
            out = f"read {member}, a link out of the folder"
    return root / "export", out


def _folders_problem(zipped: Path, report) -> str | None:
    """Why reading ``zipped`` as one recording was wrong: tables from several folders."""
    folders = {Path(f).parent.name for f in report.files}
    if len(folders) > 1:
        return f"tables of {len(folders)} folders read as one recording: {sorted(folders)}"
    return None


def export_garbage(found: dict) -> str | None:
    """Why an accepted export is implausible (module docstring), or None."""
    if found["problem"] is not None:
        return found["problem"]
    rec, _ = found["result"]
    acc = float(np.median(np.linalg.norm(rec.acc, axis=-1)))
    gyro = float(np.percentile(np.linalg.norm(rec.gyro, axis=-1), 99))
    if not 6.0 <= acc <= 14.0:
        return f"median |acc| {acc:.3g} m/s^2: a walk's is about 9.8"
    if not 0.5 <= gyro <= 30.0:
        return f"99th percentile |gyro| {gyro:.3g} rad/s: a walking shank's is 2-15"
    return None
