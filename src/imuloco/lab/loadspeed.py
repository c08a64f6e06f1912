"""Speed of loading motion folders (``imuloco bench --load DIR ...``).

For each folder, every ``*.bvh`` is read five ways, each over the whole folder:

- ``numpy``: the reference, a plain numpy text parse of the same files (``numpy.loadtxt`` of
  each MOTION block, nothing else);
- ``arrow``: the same blocks parsed by pyarrow's CSV reader (one-space delimiter, float64
  columns declared, one thread), when pyarrow is installed: whether another library's text
  parser would beat numpy's on these files;
- ``old``: the reader of an earlier commit (``--against REV``), loaded from git with the
  rotation, kinematics, up-axis and number-parsing modules of that commit, on today's Motion
  and Skeleton;
- ``reader``: today's :func:`imuloco.io.bvh.read_bvh` with no cache;
- ``cold``: loading through the clip cache (:mod:`imuloco.io.cache`) into an empty cache
  folder (parse, hash and write each entry);
- ``warm``: the same again, every clip from the cache.

With ``--against``, every clip is also read once more by both readers (untimed) and the
largest absolute difference between their Motions (rotations, root path, offsets, End Sites)
is reported, with the clips whose joints, frame rate or refusal differ: a faster reader must
give the same Motions.

Files are read once beforehand so that every way finds them in the page cache. Frames per
second count the frames of the clips a way read (the old reader refuses some real rigs: the
table says how many). Times are wall
clock and this process's CPU time (``*_cpu``; on a shared machine other processes inflate wall
times), with the 1-minute load average when measured; the table shows CPU times.
"""

from __future__ import annotations

import importlib.util
import io
import json
import os
import re
import subprocess
import sys
import tempfile
import time
import types
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from imuloco.errors import FormatError, InputError, MissingInputError
from imuloco.io.atomic import atomic_write
from imuloco.io.bvh import read_bvh
from imuloco.io.cache import read_motion_cached

WAYS = ("numpy", "arrow", "old", "reader", "cold", "warm")
_MOTION = re.compile(r"^\s*MOTION\s*$", re.MULTILINE)


def numpy_parse(path: Path) -> int:
    """The reference: ``numpy.loadtxt`` of the MOTION block (after its two header lines);
    returns the frame count."""
    text = path.read_text(encoding="latin-1")
    block = text[_MOTION.search(text).end():].lstrip().split("\n", 2)[2]
    return len(np.loadtxt(io.StringIO(block), comments=None, ndmin=2))


def arrow_parse(path: Path) -> int:
    """The MOTION block (as :func:`numpy_parse` cuts it) read by ``pyarrow.csv.read_csv``;
    returns the frame count."""
    import pyarrow as pa  # the [dist] extra's
    import pyarrow.csv as pcsv

    text = path.read_text(encoding="latin-1")
    block = text[_MOTION.search(text).end():].lstrip().split("\n", 2)[2]
    # fields between single spaces (a trailing space makes an empty last column, read as null)
    width = len(block[:block.find("\n")].rstrip("\r").split(" "))
    names = [f"c{i}" for i in range(width)]
    try:
        return pcsv.read_csv(
            pa.BufferReader(block.encode("latin-1")),
            read_options=pcsv.ReadOptions(column_names=names, use_threads=False),
            parse_options=pcsv.ParseOptions(delimiter=" "),
            convert_options=pcsv.ConvertOptions(
                column_types=dict.fromkeys(names, pa.float64())),
        ).num_rows
    except pa.ArrowInvalid as e:  # counted as refused by the bench
        raise FormatError(path, None, f"pyarrow's CSV reader: {e}") from None


def module_at(rev: str, relpath: str, name: str) -> types.ModuleType:
    """The module ``relpath`` of the repository at commit ``rev`` (for the comparison only)."""
    root = Path(__file__).resolve().parents[3]
    try:
        src = subprocess.run(["git", "-C", str(root), "show", f"{rev}:{relpath}"],
                             capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError) as e:
        why = getattr(e, "stderr", None) or str(e)  # git's own words: unknown revision, ...
        raise InputError(f"--against {rev}: cannot read {relpath} from git in {root} "
                         f"(a commit of a source checkout is needed): {why.strip()}") from None
    module = types.ModuleType(name)
    sys.modules[name] = module  # dataclasses look their module up there
    exec(compile(src, f"{rev}:{relpath}", "exec"), module.__dict__)  # noqa: S102 (own code)
    return module


# The reader's modules, each after those it imports: the old reader runs on all of them as they
# were at its commit (a module the commit lacks is skipped).
_READER_MODULES = ("ops/rotations.py", "ops/kinematics.py", "io/upaxis.py", "io/numtext.py",
                   "io/bvh.py")


def old_reader(rev: str) -> Callable[[Path], Any]:
    """``read_bvh`` of commit ``rev``, with that commit's rotation, kinematics, up-axis and
    number-parsing functions (today's Motion and Skeleton)."""
    old: dict[str, types.ModuleType] = {}  # today's module name -> the old module
    for relpath in _READER_MODULES:
        current = "imuloco." + relpath.removesuffix(".py").replace("/", ".")
        try:
            module = module_at(rev, f"src/imuloco/{relpath}",
                               "imuloco_old_" + relpath.removesuffix(".py").replace("/", "_"))
        except ValueError:
            if relpath == "io/bvh.py":
                raise
            continue
        for attr, value in list(vars(module).items()):  # today's functions -> the old ones
            source = old.get(getattr(value, "__module__", None) or "")
            if source is not None and hasattr(source, attr):
                setattr(module, attr, getattr(source, attr))
        old[current] = module
    return old["imuloco.io.bvh"].read_bvh


def motion_difference(a: Any, b: Any) -> float:
    """The largest absolute difference between two Motions' rotations, root paths, offsets
    and End Sites; inf when their joints, parents, frame rates or End Site joints differ."""
    ska, skb = a.skeleton, b.skeleton
    if (ska.names != skb.names or a.fps != b.fps or ska.end_sites.keys() != skb.end_sites.keys()
            or not np.array_equal(ska.parents, skb.parents)
            or a.rotations.shape != b.rotations.shape):
        return float("inf")
    pairs = [(a.rotations, b.rotations), (a.root, b.root), (ska.offsets, skb.offsets)]
    pairs += [(ska.end_sites[k], skb.end_sites[k]) for k in ska.end_sites]
    return max(float(np.max(np.abs(np.asarray(x) - np.asarray(y)), initial=0.0))
               for x, y in pairs)


def compare_readers(files: list[Path], old: Callable[[Path], Any], progress: bool
                    ) -> tuple[float, int]:
    """The largest :func:`motion_difference` between ``old``'s and today's Motion over
    ``files``, and how many clips differ otherwise (one reader refuses what the other reads,
    or they refuse it with different messages)."""
    worst, mismatched = 0.0, 0
    for f in tqdm(files, desc=f"{files[0].parent.name} same?", disable=not progress,
                  unit="clip", leave=False):
        got = []
        for read in (old, read_bvh):
            try:
                got.append(read(f))
            except FormatError as e:
                got.append(str(e))
        if isinstance(got[0], str) or isinstance(got[1], str):
            mismatched += got[0] != got[1]
        else:
            worst = max(worst, motion_difference(*got))
    return worst, mismatched


def _timed(files: list[Path], read: Callable[[Path], Any], desc: str, progress: bool
           ) -> tuple[float, float, list[int]]:
    """Wall and CPU seconds of reading ``files``, and the indices of the files refused with a
    FormatError (the old reader refuses some real rigs)."""
    refused = []
    wall, cpu = time.perf_counter(), time.process_time()
    for i, f in enumerate(tqdm(files, desc=desc, disable=not progress, unit="clip",
                               leave=False)):
        try:
            read(f)
        except FormatError:
            refused.append(i)
    return time.perf_counter() - wall, time.process_time() - cpu, refused


def load_benchmark(folders: Sequence[str | Path], out: str | Path | None = None,
                   against: str | None = None, progress: bool = True) -> list[dict[str, Any]]:
    """Time loading each folder (and all together) the ways of :data:`WAYS`; write
    ``load.json`` and ``load.md`` to ``out``. ``against``: the commit of the ``old`` reader
    (skipped when None)."""
    old = old_reader(against) if against else None
    arrow = importlib.util.find_spec("pyarrow") is not None
    records = []
    for folder in map(Path, folders):
        files = sorted(folder.glob("*.bvh"))
        if not files:
            raise MissingInputError(f"no .bvh files in {folder}")
        counts = [numpy_parse(f) for f in files]  # and into the page cache for every way
        frames = sum(counts)
        rec: dict[str, Any] = {"folder": folder.name, "clips": len(files), "frames": frames,
                               "mbytes": round(sum(f.stat().st_size for f in files) / 1e6, 1)}
        with tempfile.TemporaryDirectory(prefix="imuloco-load-") as tmp:
            saved = os.environ.get("IMULOCO_CACHE")
            os.environ["IMULOCO_CACHE"] = tmp
            try:
                ways: dict[str, Callable[[Path], Any]] = {"numpy": numpy_parse}
                if arrow:
                    ways["arrow"] = arrow_parse
                if old is not None:
                    ways["old"] = old
                ways |= {"reader": read_bvh, "cold": read_motion_cached,
                         "warm": read_motion_cached}
                for way, read in ways.items():
                    wall, cpu, refused = _timed(files, read, f"{folder.name} {way}", progress)
                    rec[f"{way}_s"], rec[f"{way}_cpu_s"] = round(wall, 3), round(cpu, 3)
                    rec[f"{way}_frames"] = frames - sum(counts[i] for i in refused)
                    rec[f"{way}_fps"] = round(rec[f"{way}_frames"] / wall)
                    rec[f"{way}_refused"] = len(refused)
            finally:
                if saved is None:
                    del os.environ["IMULOCO_CACHE"]
                else:
                    os.environ["IMULOCO_CACHE"] = saved
        rec["load_avg"] = round(os.getloadavg()[0], 2)
        if old is not None:
            rec["old_max_abs_diff"], rec["old_mismatched"] = compare_readers(files, old, progress)
        records.append(rec)
    records.append(_total(records))
    if out is not None:
        out = Path(out)
        with atomic_write(out / "load.json", "w") as f:
            json.dump({"against": against, "records": records}, f, indent=2)
        with atomic_write(out / "load.md", "w") as f:
            f.write(table(records, against) + "\n")
    return records


def _total(records: list[dict[str, Any]]) -> dict[str, Any]:
    tot: dict[str, Any] = {"folder": "all"}
    for key in records[0]:
        if key.endswith(("_s", "clips", "frames", "mbytes", "_refused")):
            tot[key] = round(sum(r[key] for r in records), 3)
    for way in WAYS:
        if f"{way}_s" in tot:
            tot[f"{way}_fps"] = round(tot[f"{way}_frames"] / tot[f"{way}_s"])
    tot["load_avg"] = records[-1]["load_avg"]
    if "old_max_abs_diff" in records[0]:
        tot["old_max_abs_diff"] = max(r["old_max_abs_diff"] for r in records)
        tot["old_mismatched"] = sum(r["old_mismatched"] for r in records)
    return tot


def table(records: list[dict[str, Any]], against: str | None = None) -> str:
    """Markdown: per folder, this process's CPU seconds (and frames/s) of each way, and the
    ratios that matter, by CPU time (wall times, inflated on a shared machine, are in the
    JSON)."""
    ways = [w for w in WAYS if f"{w}_s" in records[0]]
    head = ["folder", "clips", "frames"] + [
        f"{'old (' + against[:7] + ')' if w == 'old' and against else w} CPU s (frames/s)"
        for w in ways]
    head += (["arrow speed / numpy's"] if "arrow" in ways else []) + [
        "reader speed / numpy's", "warm / cold speed"] + (
        ["reader speed / old's", "old refused", "max abs diff to old's Motions",
         "clips read differently"] if "old" in ways else []) + ["load avg"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in records:
        def fps(way: str, r: dict[str, Any] = r) -> float:
            return r[f"{way}_frames"] / max(r[f"{way}_cpu_s"], 1e-9)

        row = [r["folder"], str(r["clips"]), f"{r['frames']:,}"]
        row += [f"{r[w + '_cpu_s']:.2f} ({fps(w):,.0f})" for w in ways]
        if "arrow" in ways:
            row.append(f"{fps('arrow') / fps('numpy'):.2f}x")
        row += [f"{fps('reader') / fps('numpy'):.2f}x", f"{fps('warm') / fps('cold'):.1f}x"]
        if "old" in ways:
            row += [f"{fps('reader') / fps('old'):.2f}x", f"{r['old_refused']} clips"]
            row += ([f"{r['old_max_abs_diff']:.3g}", str(r["old_mismatched"])]
                    if "old_max_abs_diff" in r else ["", ""])
        row.append(f"{r['load_avg']:.1f}")
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)
