"""Many recordings at once: one walker per phone log, reconstructed in parallel.

:func:`run_batch` runs :func:`imuloco.app.pipeline.reconstruct_file` on every recording with one
model, in ``jobs`` worker processes (joblib, the ``[dist]`` extra; serially without it), and
writes per recording ``NAME.bvh`` and ``NAME.json`` (the reconstruction report: import,
calibration, gait parameters, plausibility checks), then ``summary.csv`` and ``summary.json``
with one row per walker (cadence, speed, step and stride length, ...). A recording that fails
gets a row with its error; the others go on.

The model is fitted (or loaded) once, saved to a temporary model file and loaded once per
worker process, so workers receive a path, never a pickled model.
"""

from __future__ import annotations

import csv
import functools
import glob as globmod
import json
import logging
import os
import tempfile
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

# summary columns after name and status, taken from the report's gait parameters
GAIT_COLUMNS = ("cadence_spm", "cadence_rhythm_spm", "speed_mps", "step_length_m",
                "stride_length_m", "steps", "stance_pct", "double_support_pct")
COLUMNS = ("name", "recording", "status", "frames", "duration_s", *GAIT_COLUMNS,
           "signal_cadence_spm", "seconds", "error")


def find_recordings(paths: Sequence[str | Path] = (), patterns: Sequence[str] = ()
                    ) -> list[Path]:
    """The recordings named and matched by glob ``patterns`` (``**`` recurses), sorted within
    each pattern, duplicates dropped, in the order given."""
    found: list[Path] = [Path(p) for p in paths]
    for pattern in patterns:
        matches = sorted(globmod.glob(str(pattern), recursive=True))
        if not matches:
            log.warning("no recording matches %r", pattern)
        found += [Path(m) for m in matches]
    seen, out = set(), []
    for p in found:
        key = os.path.normpath(p.absolute())  # not resolve(): two links are two walkers
        if key not in seen:
            seen.add(key)
            out.append(p)
    return out


def output_names(paths: Sequence[Path]) -> list[str]:
    """A distinct output name per recording: its stem, with its folder's name (then a number)
    prepended where stems repeat (``walker1/log.csv``, ``walker2/log.csv``)."""
    stems = [p.stem for p in paths]
    names = [f"{p.parent.name}_{p.stem}" if stems.count(p.stem) > 1 else p.stem for p in paths]
    out, used = [], set()
    for n in names:
        cand, k = n, 2
        while cand in used:
            cand, k = f"{n}_{k}", k + 1
        used.add(cand)
        out.append(cand)
    return out


@functools.lru_cache(maxsize=2)
def _load(model_path: str):
    """The fitted method of a model file, loaded once per process."""
    from imuloco.methods import load_model

    return load_model(model_path)


def reconstruct_one(recording: str | Path, out_dir: str | Path, name: str, model_path: str,
                    placement: str = "right_ankle", fmt: str = "auto", calibrate: bool = True,
                    overwrite: bool = False, platform: str | None = None,
                    skeleton: str | None = None) -> dict[str, Any]:
    """Reconstruct one recording, write ``NAME.bvh`` and ``NAME.json`` into ``out_dir``.

    Returns its summary row (see :data:`COLUMNS`); errors are caught and reported in the row.
    """
    from imuloco.app.pipeline import reconstruct_file
    from imuloco.io.bvh import write_bvh

    t0 = time.perf_counter()
    row: dict[str, Any] = {"name": name, "recording": str(recording)}
    try:
        motion, report = reconstruct_file(recording, placement=placement, fmt=fmt,
                                          calibrate=calibrate, fitted=_load(model_path),
                                          platform=platform, skeleton=skeleton)
        out = Path(out_dir)
        write_bvh(motion, out / f"{name}.bvh", overwrite=overwrite)
        (out / f"{name}.json").write_text(json.dumps(report, indent=2) + "\n")
    except Exception as e:  # noqa: BLE001 - one bad recording must not stop the batch
        log.warning("%s: %s: %s", recording, type(e).__name__, e)
        row.update(status="error", error=f"{type(e).__name__}: {e}")
    else:
        gait = report["gait"]
        row.update(status="ok", frames=motion.num_frames,
                   duration_s=report["motion"]["duration_s"],
                   **{k: gait.get(k) for k in GAIT_COLUMNS},
                   signal_cadence_spm=report["signal_cadence_spm"], error="")
    row["seconds"] = round(time.perf_counter() - t0, 3)
    return {k: row.get(k) for k in COLUMNS}


def _results(tasks: list[dict], jobs: int) -> Iterator[dict]:
    """Run :func:`reconstruct_one` on every task, yielding rows as they finish."""
    if jobs != 1 and len(tasks) > 1:
        try:
            from joblib import Parallel, delayed
        except ImportError:
            log.warning("joblib is not installed (pip install imuloco[dist]): running serially")
        else:
            yield from Parallel(n_jobs=jobs, return_as="generator_unordered")(
                delayed(reconstruct_one)(**t) for t in tasks)
            return
    for t in tasks:
        yield reconstruct_one(**t)


def run_batch(recordings: Sequence[str | Path], out_dir: str | Path, jobs: int = 1,
              model: str | Path | None = None, method: str | None = None,
              placement: str = "right_ankle", fmt: str = "auto", calibrate: bool = True,
              overwrite: bool = False, progress: bool = False, fitted=None,
              platform: str | None = None, skeleton: str | Path | None = None
              ) -> dict[str, Any]:
    """Reconstruct every recording into ``out_dir`` (see the module docstring).

    Parameters
    ----------
    recordings : log files (see :func:`imuloco.sensors.reallog.read_log`), one walker each.
    out_dir : folder for the outputs (created).
    jobs : worker processes (``-1``: one per CPU; ``1``: in this process).
    model, method, placement : the model, as :func:`imuloco.app.pipeline.choose_method` picks it.
    fmt, calibrate, platform : see :func:`imuloco.app.pipeline.reconstruct_file`.
    overwrite : replace existing outputs (otherwise refuse before starting).
    progress : a progress bar (tqdm) on stderr.
    fitted : an already fitted method (skips the choice).
    skeleton : a motion file of the user's rig: every BVH comes out on it (checked before
        starting; see :func:`imuloco.app.pipeline.onto_rig`).

    Returns
    -------
    The summary (also written to ``summary.json``): ``model``, ``method``, ``jobs``,
    ``model_seconds`` (choosing the model), ``seconds`` (reconstructing), ``ok``, ``failed``,
    ``frames`` (reconstructed) and ``recordings`` (rows in input order).
    """
    from tqdm.auto import tqdm

    from imuloco.app.pipeline import choose_method

    paths = [Path(p) for p in recordings]
    if not paths:
        raise ValueError("no recordings given")
    names = output_names(paths)
    out = Path(out_dir)
    files = [out / f"{n}{ext}" for n in names for ext in (".bvh", ".json")]
    files += [out / "summary.csv", out / "summary.json"]
    taken = [str(p) for p in files if p.exists()]
    if taken and not overwrite:
        raise FileExistsError(f"{', '.join(taken[:5])}{' ...' if len(taken) > 5 else ''} "
                              "exist(s); pass overwrite=True (--force) to replace")
    if skeleton is not None:
        from imuloco.app.pipeline import load_rig

        load_rig(skeleton)  # refuse a rig that cannot be mapped before any work
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    if fitted is None:
        fitted, note = choose_method(method, model, placement, progress=progress)
    else:
        note = f"given fitted method {fitted.name!r}"
    model_seconds = time.perf_counter() - t0
    t0 = time.perf_counter()
    rows: dict[str, dict] = {}
    with tempfile.TemporaryDirectory(prefix="imuloco-batch-") as tmp:
        model_path = str(fitted.save(Path(tmp) / "model.npz"))
        tasks = [{"recording": str(p), "out_dir": str(out), "name": n,
                  "model_path": model_path, "placement": placement, "fmt": fmt,
                  "calibrate": calibrate, "overwrite": overwrite, "platform": platform,
                  "skeleton": None if skeleton is None else str(skeleton)}
                 for p, n in zip(paths, names)]
        bar = tqdm(total=len(tasks), desc="batch", unit="rec", disable=not progress)
        for row in _results(tasks, jobs):
            rows[row["name"]] = row
            bar.set_postfix_str(f"{row['name']}: {row['status']}")
            bar.update()
        bar.close()
    ordered = [rows[n] for n in names]
    seconds = time.perf_counter() - t0
    summary = {"model": note, "method": fitted.name, "jobs": jobs,
               "model_seconds": round(model_seconds, 2), "seconds": round(seconds, 2), "ok": sum(r["status"] == "ok" for r in ordered),
               "failed": sum(r["status"] != "ok" for r in ordered),
               "frames": sum(r["frames"] or 0 for r in ordered), "recordings": ordered}
    with open(out / "summary.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=COLUMNS)
        writer.writeheader()
        writer.writerows(ordered)
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary
