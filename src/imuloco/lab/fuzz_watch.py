"""The ``watch`` reader kind of ``imuloco bench fuzz`` (issue 46): a second sensor, read as
``reconstruct`` reads it.

Seeds (:func:`watch_seeds`) are one shin phone and one wrist watch, simulated after a stand
with two stomps (2 s of it, then the stomps, then a walk): an iPhone's Sensor Logger export
with the watch's ``WristMotion.csv`` as a folder and as a zip (read by
:func:`~imuloco.sensors.reallog.read_log`), and the two sensors as two generic CSVs on
clocks of their own (read by :func:`~imuloco.sensors.multi.read_sensors`, the watch given as
``--sensor left_wrist=FILE``: its clock found by the stomps). The pair's folder is named after
the watch's true clock offset (``pair+1.300``), which no edit touches.

The structured attacks (:func:`watch_attack`):

* exports: ``WristMotion.csv`` with "Standardise Units & Frames" on (m/s^2, Android sign), its
  gravity columns zero or constant, a required column dropped or renamed, its clock shifted
  (by -4 to +4 s, or its ns read as ms), thinned to 50 or 25 Hz, its rows reversed, the
  watch's table alone (no phone), or (zip) in a second folder too;
* pairs: the clocks apart by a fresh offset of -2.5..+2.5 s (either device starting first),
  the stomps taken out of one or both sensors (a still stand instead), the watch's times
  scaled (in ms) or the watch's table cut to its first second.

:func:`watch_garbage` judges an accepted case: both sensors read (a watch dropped silently is
garbage), finite values, each sensor's median |acc| 6-14 m/s^2 and 99th percentile |gyro|
0.2-40 rad/s (below 40 only when a cut file left less than a second of the walk); a pair's offset within one frame (1/30 s) of its folder's, when the case did not
change the clocks' truth.
"""

from __future__ import annotations

import random
import re
from pathlib import Path

import numpy as np

from imuloco.core.motion import Motion
from imuloco.io.sensorlog import WATCH_FILE, write_generic_csv
from imuloco.io.sensorwrite import write_sensor_logger
from imuloco.lab.mutations import Files, unzip, zip_files
from imuloco.sensors.multi import read_sensors
from imuloco.sensors.reallog import read_log
from imuloco.sensors.simulate import STOMP_AT_S, simulate, still_start

PAIR = ["right_ankle", "left_wrist"]
LEAD_S = 2.0  # seconds of standing before the stomps: room to start either device late
STAND_S = LEAD_S + STOMP_AT_S[-1] + 0.3  # seconds of standing in all
WALK_S = 3.0  # seconds of walking after the stand
SEED_OFFSET_S = 1.3  # the pair seed's watch clock runs this far behind the phone's
FRAME_S = 1 / 30
PAIR_DIR = re.compile(r"^pair([+-]\d+\.\d+)$")  # a pair's folder, named after its offset
_WATCH_NEEDS = ("time", "accelerationX", "gravityY", "rotationRateZ")


def watch_seeds(clip: Motion, work: Path) -> list[Files]:
    """The three seeds (module docstring) from a walking ``clip``, written through ``work``."""
    rec = simulate(still_start(clip, STAND_S), PAIR, 100.0, "phone", 5,
                   stomps=[LEAD_S + t for t in STOMP_AT_S])
    keep = rec.times <= STAND_S + WALK_S
    rec = rec.select(PAIR)
    rec.times, rec.acc, rec.gyro = rec.times[keep], rec.acc[keep], rec.gyro[keep]
    rec.orientation = rec.orientation[keep]
    export = {f"export/{p.name}": p.read_bytes()
              for p in write_sensor_logger(rec, work / "watch-export", overwrite=True)}
    zipped = zip_files({k.replace("export/", "Walk/"): v for k, v in export.items()})
    return [export, {"export.zip": zipped}, _pair(rec, work, SEED_OFFSET_S)]


def _pair(rec, work: Path, offset: float) -> Files:
    """The pair's two CSVs, the device whose clock is behind starting that late."""
    files = {}
    for p, behind in zip(PAIR, (max(-offset, 0.0), max(offset, 0.0))):
        one = rec.select([p])
        t = one.times - behind
        keep = t >= 0.0
        one.times, one.acc, one.gyro, one.orientation = t[keep], one.acc[keep], one.gyro[keep], None
        path = write_generic_csv(one, work / f"{p}.csv", overwrite=True)
        files[f"pair{offset:+.3f}/{p}.csv"] = path.read_bytes()
    return files


def watch_attack(files: Files, rng: random.Random) -> tuple[str, Files]:
    """One structured attack (module docstring) on a seed, by the seed's kind."""
    first = next(iter(files))
    if first == "export.zip":
        members = unzip(files[first])
        label, members = _export_attack(members, "Walk/", rng, zipped=True)
        return label, {first: zip_files(members)}
    if first.startswith("export/"):
        return _export_attack(dict(files), "export/", rng, zipped=False)
    return _pair_attack(files, rng)


def _rows(data: bytes) -> tuple[list[str], np.ndarray]:
    lines = data.decode().splitlines()
    return lines[0].split(","), np.array([[float(c) for c in ln.split(",")] for ln in lines[1:]])


def _table(header: list[str], rows: np.ndarray, ints: int = 0) -> bytes:
    """CSV bytes; the first ``ints`` columns written as integers (Unix ns)."""
    out = [",".join(header)]
    for r in rows:
        out.append(",".join([*(str(int(v)) for v in r[:ints]), *(f"{v:.9g}" for v in r[ints:])]))
    return ("\n".join(out) + "\n").encode()


def _export_attack(files: Files, folder: str, rng: random.Random, zipped: bool
                   ) -> tuple[str, Files]:
    watch = folder + WATCH_FILE
    header, rows = _rows(files[watch])
    cols = {h: i for i, h in enumerate(header)}
    grav = [cols[f"gravity{a}"] for a in "XYZ"]
    kinds = ["standardised", "gravity-zero", "gravity-constant", "column", "shift", "ms",
             "thin", "reversed", "watch-only"] + (["second-folder"] if zipped else [])
    kind = rng.choice(kinds)
    label = f"attack:watch-{kind}"
    if kind == "standardised":
        sig = grav + [cols[f"acceleration{a}"] for a in "XYZ"]
        rows[:, sig] *= -9.80665
    elif kind == "gravity-zero":
        rows[:, grav] = 0.0
    elif kind == "gravity-constant":
        rows[:, grav] = rng.choice((0.0, 1.0, -1.0, 9.81))
    elif kind == "column":
        name = rng.choice(_WATCH_NEEDS)
        if rng.random() < 0.5:
            header[cols[name]] = name + "_renamed"
            label += f"-renamed-{name}"
        else:
            keep = [i for i in range(len(header)) if i != cols[name]]
            header, rows = [header[i] for i in keep], rows[:, keep]
            label += f"-dropped-{name}"
        cols = {h: i for i, h in enumerate(header)}
    elif kind == "shift":
        s = rng.choice((-4.0, -1.0, -0.3, 0.3, 1.0, 4.0))
        rows[:, 0] += s * 1e9
        label += f"{s:+g}s"
    elif kind == "ms":
        rows[:, 0] = np.round(rows[:, 0] / 1e6)
    elif kind == "thin":
        step = rng.choice((2, 4))
        rows = rows[::step]
        label += f"-{100 // step}Hz"
    elif kind == "reversed":
        rows = rows[::-1]
    data = _table(header, rows, ints=1 if "time" in cols else 0)
    files[watch] = data
    if kind == "watch-only":
        files = {k: v for k, v in files.items() if k == watch or k.endswith("Metadata.csv")}
    elif kind == "second-folder":
        files["Other/" + WATCH_FILE] = data
    return label, files


def _pair_attack(files: Files, rng: random.Random) -> tuple[str, Files]:
    (ankle_name, ankle), (_, wrist) = list(files.items())[:2]
    truth = float(PAIR_DIR.match(Path(ankle_name).parent.name).group(1))
    head_a, a = _rows(ankle)
    head_w, w = _rows(wrist)
    a[:, 0] += max(-truth, 0.0)  # both back on one clock, the phone's from its start
    w[:, 0] += max(truth, 0.0)
    kind = rng.choice(("offset", "no-stomp", "no-stomp-both", "ms", "short"))
    label = f"attack:pair-{kind}"
    if kind == "offset":
        truth = round(rng.uniform(-2.5, 2.5), 3)
        label += f"{truth:+.3f}s"
    a[:, 0] -= max(-truth, 0.0)
    w[:, 0] -= max(truth, 0.0)
    a, w = a[a[:, 0] >= 0], w[w[:, 0] >= 0]
    if kind.startswith("no-stomp"):
        for t, behind in ((w, max(truth, 0.0)), (a, max(-truth, 0.0)))[:1 + (kind != "no-stomp")]:
            stand = t[:, 0] < LEAD_S + STOMP_AT_S[-1] + 0.1 - behind  # the stand, own clock
            t[stand, 1:] = t[0, 1:]  # a still stand: no jolt at all
    elif kind == "ms":
        w[:, 0] *= 1000.0
    elif kind == "short":
        w = w[w[:, 0] <= w[0, 0] + 1.0]
    folder = f"pair{truth:+.3f}" if kind == "offset" else Path(ankle_name).parent.name
    return label, {f"{folder}/{PAIR[0]}.csv": _table(head_a, a),
                   f"{folder}/{PAIR[1]}.csv": _table(head_w, w)}


def read_watch(paths: list[Path]) -> dict:
    """Read a case as ``reconstruct`` does: ``{"result": (recording, report), "truth":
    the watch's true clock offset or None}``; the library's refusals are raised."""
    first = paths[0]
    if first.name == "export.zip":
        return {"result": read_log(first), "truth": None}
    if first.parent.name == "export":
        return {"result": read_log(first.parent), "truth": None}
    found = PAIR_DIR.match(first.parent.name)
    return {"result": read_sensors(first, [(PAIR[1], paths[1])], placement=PAIR[0]),
            "truth": float(found.group(1)) if found else None}


def watch_garbage(found: dict) -> str | None:
    """Why an accepted case is implausible (module docstring), or None."""
    rec, report = found["result"]
    if rec.placements != PAIR:
        return f"read sensors {rec.placements}, expected {PAIR}"
    if not (np.isfinite(rec.acc).all() and np.isfinite(rec.gyro).all()):
        return "non-finite values"
    for k, p in enumerate(PAIR):
        acc = float(np.median(np.linalg.norm(rec.acc[:, k], axis=-1)))
        gyro = float(np.percentile(np.linalg.norm(rec.gyro[:, k], axis=-1), 99))
        if not 6.0 <= acc <= 14.0:
            return f"{p}: median |acc| {acc:.3g} m/s^2: a walk's is about 9.8"
        moved = rec.times[-1] - rec.times[0] > STAND_S + 1.0  # a second of the walk in it
        if not (0.2 if moved else 0.0) <= gyro <= 40.0:
            return f"{p}: 99th percentile |gyro| {gyro:.3g} rad/s, implausible for a walk"
    truth = found["truth"]
    if truth is not None and abs(report.sensors[1].offset_s - truth) > FRAME_S:
        return (f"the watch's clock put {report.sensors[1].offset_s:+.3f} s off, its true "
                f"offset is {truth:+.3f} s")
    return None
