"""Do the commands still write what they wrote? A key-by-key check of every output file.

    python benchmarks/report_equivalence.py capture DIR        # outputs of this tree into DIR
    python benchmarks/report_equivalence.py compare GOLDEN [--work DIR]

``capture`` runs, with the ``imuloco`` of this tree: ``demo``; ``simulate`` of a bundled walk
on the right ankle, the right foot and the lower back and ``reconstruct --report`` of each;
``reconstruct --piece-seconds 10 --report`` of a 45 s recording (the right-ankle and the
lower-back walk repeated end to end); ``batch`` of 3 recordings; and
``bench --method mean,ridge --split heldout-styles --limit 4``; each command's printed output
goes to ``stdout/NN-COMMAND.out``. ``compare`` captures again into ``--work`` (a temporary
folder by default) and compares every file of GOLDEN with its namesake: JSON key by key, CSV and
Parquet cell by cell (numbers within 1e-9), BVH and other text line by line (numbers within
1e-9), printed output line by line (numbers followed by a unit of time, as ``166 s``, are
timings), everything else (video, images) by existence. Timings and dates
(``seconds``, ``trained_at``, ...: see ``IGNORED``) are not compared. Keys, columns or files
present only in the new output are listed as additions (an allowed extension) without failing,
as are keys in another order (JSON objects are unordered); a missing or changed one fails.
Prints one line per difference and exits 1 on any.

    PYTHONPATH=OLD/src python benchmarks/report_equivalence.py capture GOLDEN   # an old tree
    python benchmarks/report_equivalence.py compare GOLDEN --work NEW            # this tree
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pyarrow.parquet as pq

SAMPLE = Path(__file__).resolve().parents[1] / "src" / "imuloco" / "data" / "sample"
WALKS = ["dataset-2_walk_normal_001", "dataset-2_walk_active_001", "dataset-2_walk_feminine_001"]
PLACEMENTS = ["right_ankle", "right_foot", "lower_back"]
# Keys whose values are timings or dates: they differ between any two runs of the same code.
IGNORED = {"seconds", "trained_at", "elapsed_s", "wall_s", "fit_s", "reconstruct_s",
           "train_s", "time_s", "timings", "created", "date", "started", "finished",
           "recordings_per_s", "realtime_factor", "fit_seconds", "reconstruct_seconds",
           "model_seconds", "offline_fps", "online_latency_ms_p50", "online_latency_ms_p99",
           # a model file's size: its header holds the training's date
           "model_bytes"}
TOL = 1e-9
# what follows a printed number that is a timing: a unit of time or of a rate
TIMING = re.compile(r"\s*(?:s|ms|min|seconds?|[a-z ]*/(?:s|min)|x real ?time)\b")
NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


# where run() writes each command's printed output, and how many it has run
STDOUT: list = [None, 0]


def run(*args: str | Path) -> None:
    """Run one ``imuloco`` command; stop with its output if it fails. Its standard output is
    kept in ``stdout/NN-COMMAND.out`` (progress bars, on standard error, are not)."""
    cmd = ["imuloco", *map(str, args)]
    done = subprocess.run(cmd, check=False, capture_output=True, text=True)
    if done.returncode:
        sys.exit(f"{' '.join(cmd)} failed:\n{done.stdout}{done.stderr}")
    STDOUT[1] += 1
    (STDOUT[0] / f"{STDOUT[1]:02d}-{args[0]}.out").write_text(done.stdout)


def repeat_csv(src: Path, dst: Path, seconds: float) -> None:
    """A generic CSV log repeated end to end (times shifted) until it lasts ``seconds``."""
    with src.open() as f:
        header, *rows = list(csv.reader(f))
    times = [float(r[0]) for r in rows]
    span = times[-1] - times[0] + 0.01
    reps = math.ceil(seconds / span)
    with dst.open("w", newline="") as f:
        out = csv.writer(f)
        out.writerow(header)
        for k in range(reps):
            out.writerows([f"{t + k * span:.6f}", *r[1:]] for t, r in zip(times, rows))


def capture(out: Path) -> None:
    """Every command's outputs into ``out`` (emptied first)."""
    shutil.rmtree(out, ignore_errors=True)
    rec, res = out / "recordings", out / "reconstruct"
    rec.mkdir(parents=True)
    res.mkdir()
    STDOUT[:] = [out / "stdout", 0]
    STDOUT[0].mkdir()
    run("demo", "--out", out / "demo")
    walk = SAMPLE / f"{WALKS[0]}.bvh"
    for p in PLACEMENTS:
        run("simulate", walk, "--placement", p, "-o", rec / f"{p}.csv")
        run("reconstruct", rec / f"{p}.csv", "--placement", p, "-o", res / f"{p}.bvh",
            "--report", res / f"{p}.json")
    for p in ["right_ankle", "lower_back"]:
        repeat_csv(rec / f"{p}.csv", rec / f"long_{p}.csv", 45.0)
        run("reconstruct", rec / f"long_{p}.csv", "--placement", p, "--piece-seconds", 10,
            "-o", res / f"pieces_{p}.bvh", "--report", res / f"pieces_{p}.json")
    walkers = []
    for name in WALKS:
        run("simulate", SAMPLE / f"{name}.bvh", "-o", rec / f"{name}.csv")
        walkers.append(rec / f"{name}.csv")
    run("batch", *walkers, "--out", out / "batch", "-j", 1)
    run("bench", "--method", "mean,ridge", "--split", "heldout-styles", "--limit", 4,
        "--out", out / "bench")


def same_number(a: float, b: float) -> bool:
    return a == b or (math.isnan(a) and math.isnan(b)) or abs(a - b) <= TOL


# (golden folder, work folder): paths in the outputs name the folder they were written to
FOLDERS = ("", "")


def compare_values(old, new, where: str, diffs: list[str], added: list[str]) -> None:
    """Append to ``diffs`` each difference between two JSON values (recursively)."""
    if isinstance(new, str) and FOLDERS[1]:
        new = new.replace(*reversed(FOLDERS))
    if isinstance(old, dict) and isinstance(new, dict):
        for key in old:
            if key in IGNORED:
                continue
            if key not in new:
                diffs.append(f"{where}.{key}: missing")
            else:
                compare_values(old[key], new[key], f"{where}.{key}", diffs, added)
        added += [f"{where}.{key}" for key in new if key not in old]
        common = [k for k in new if k in old]
        if common != [k for k in old if k in new]:
            added.append(f"{where}: keys reordered to {common}")
    elif isinstance(old, list) and isinstance(new, list):
        if len(old) != len(new):
            diffs.append(f"{where}: {len(old)} items, now {len(new)}")
        for i, (a, b) in enumerate(zip(old, new)):
            compare_values(a, b, f"{where}[{i}]", diffs, added)
    elif (isinstance(old, (int, float)) and isinstance(new, (int, float))
          and not isinstance(old, bool) and not isinstance(new, bool)):
        if type(old) is not type(new) or not same_number(float(old), float(new)):
            diffs.append(f"{where}: {old!r}, now {new!r}")
    elif old != new:
        diffs.append(f"{where}: {old!r}, now {new!r}")


def same_line(a: str, b: str) -> bool:
    """Two text lines equal but for numbers within ``TOL``."""
    if a == b:
        return True
    na, nb = NUMBER.findall(a), NUMBER.findall(b)
    return (NUMBER.sub("#", a) == NUMBER.sub("#", b) and len(na) == len(nb)
            and all(same_number(float(x), float(y)) for x, y in zip(na, nb)))


def timings_only(a: str, b: str) -> bool:
    """Two printed lines that differ only in numbers followed by a unit of time."""
    ma, mb = list(NUMBER.finditer(a)), list(NUMBER.finditer(b))
    if NUMBER.sub("#", a) != NUMBER.sub("#", b) or len(ma) != len(mb):
        return False
    return all(same_number(float(x.group()), float(y.group())) or TIMING.match(a, x.end())
               for x, y in zip(ma, mb))


def compare_csv(old: Path, new: Path, where: str, diffs: list[str], added: list[str]) -> None:
    with old.open() as f:
        a = list(csv.DictReader(f))
    with new.open() as f:
        b = list(csv.DictReader(f))
    compare_values([_cells(r) for r in a], [_cells(r) for r in b], where, diffs, added)


def _cells(row: dict) -> dict:
    """A CSV row's cells, numbers as floats."""
    out = {}
    for k, v in row.items():
        try:
            out[k] = float(v)
        except (TypeError, ValueError):
            out[k] = v
    return out


def compare_file(old: Path, new: Path, where: str, diffs: list[str], added: list[str]) -> None:
    if not new.exists():
        diffs.append(f"{where}: missing")
        return
    suffix = old.suffix.lower()
    if suffix == ".json":
        compare_values(json.loads(old.read_text()), json.loads(new.read_text()), where,
                       diffs, added)
    elif suffix == ".csv":
        compare_csv(old, new, where, diffs, added)
    elif suffix == ".parquet":
        compare_values(pq.read_table(old).to_pylist(), pq.read_table(new).to_pylist(), where,
                       diffs, added)
    elif suffix == ".out":
        a, b = old.read_text().splitlines(), new.read_text().splitlines()
        if FOLDERS[1]:
            b = [line.replace(*reversed(FOLDERS)) for line in b]
        if len(a) != len(b):
            diffs.append(f"{where}: {len(a)} lines, now {len(b)}")
        for i, (x, y) in enumerate(zip(a, b)):
            if x == y or same_line(x, y):
                continue
            if timings_only(x, y):
                added.append(f"{where}:{i + 1}: timing {x.strip()!r}, now {y.strip()!r}")
            else:
                diffs.append(f"{where}:{i + 1}: {x.strip()!r}, now {y.strip()!r}")
    elif suffix in {".bvh", ".md", ".txt"}:
        a, b = old.read_text().splitlines(), new.read_text().splitlines()
        if len(a) != len(b):
            diffs.append(f"{where}: {len(a)} lines, now {len(b)}")
        bad = [i + 1 for i, (x, y) in enumerate(zip(a, b)) if not same_line(x, y)]
        if bad and suffix == ".bvh":
            diffs.append(f"{where}: {len(bad)} lines differ, first line {bad[0]}")
        elif bad:  # tables of timings: report, never fail
            added.append(f"{where}: {len(bad)} text lines differ (timings?), first {bad[0]}")


def compare(golden: Path, work: Path) -> int:
    global FOLDERS
    capture(work)
    FOLDERS = (str(golden), str(work))
    diffs: list[str] = []
    added: list[str] = []
    files = sorted(p for p in golden.rglob("*") if p.is_file())
    for old in files:
        rel = old.relative_to(golden)
        compare_file(old, work / rel, str(rel), diffs, added)
    added += [f"{p.relative_to(work)}: new file" for p in sorted(work.rglob("*"))
              if p.is_file() and not (golden / p.relative_to(work)).exists()]
    for line in added:
        print(f"added: {line}")
    for line in diffs:
        print(f"DIFF: {line}")
    print(f"{len(files)} files compared, {len(diffs)} differences, {len(added)} additions")
    return 1 if diffs else 0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("capture").add_argument("dir", type=Path)
    cmp = sub.add_parser("compare")
    cmp.add_argument("golden", type=Path)
    cmp.add_argument("--work", type=Path)
    args = parser.parse_args()
    os.environ.setdefault("MPLBACKEND", "Agg")
    if args.command == "capture":
        capture(args.dir)
        return
    if args.work:
        sys.exit(compare(args.golden, args.work))
    with tempfile.TemporaryDirectory() as tmp:
        sys.exit(compare(args.golden, Path(tmp) / "work"))


if __name__ == "__main__":
    main()
