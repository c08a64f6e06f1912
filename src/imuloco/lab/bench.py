"""The benchmark runner: fit methods on a protocol's training clips, reconstruct every test clip
from freshly simulated sensors, measure, aggregate and report.

Protocol details fixed here (see also :mod:`imuloco.lab.protocols`):

- Test recordings: every test clip is simulated with ``seed + TEST_SEED_OFFSET`` (per clip,
  :func:`imuloco.methods.training.clip_seed`), so they never share noise with training, and
  resampled onto the clip's frame times (:func:`imuloco.methods.training.to_frames`) so that
  reconstructed frames align with the ground truth's one to one.
- Start: a reconstruction's root is turned and moved so that its first frame stands at the
  ground truth's first root position and faces its first heading
  (:func:`imuloco.measures.metrics.align_heading`); a user would give the start the same way.
- Aggregation: per motion type and ``all``, each metric is the frame-weighted mean of its
  per-clip values (for per-frame metrics this is the mean over all test frames; for ``dpv``,
  a per-clip sum by definition, clips count by their length). ``foot_skate`` ignores clips
  without ground-truth contact. ``heldout-contents`` (and ``heldout-actions``) pools the test
  clips of all its folds (each clip is tested once, by the model trained without its content),
  so its rows per motion type are the left-out contents.
- Body-part groups: ``legs_cm``, ``arms_cm`` and ``trunk_cm`` are the mean position errors of
  the canonical parts of :data:`imuloco.core.bodymap.PART_GROUPS` (heading frame at the
  pelvis), on every protocol: run ``mean`` beside a method to see each group against the mean
  pose (``results.md`` sets them side by side).
- Seeds: with ``seeds`` N > 1 each method is trained N times (seeds ``seed .. seed+N-1``,
  for the training signals and for a method's own ``seed`` hyperparameter unless the spec
  sets it) on the same test signals; each metric is the mean over the runs, ``<metric>_std`` their
  standard deviation (ddof 1; None for one run), ``mpjpe_cm_per_seed`` the runs' values.
- ``cross-dataset``: the training folders become one set on the first one's skeleton
  (:func:`imuloco.io.database.load_databases`); test clips stay on their own skeleton,
  resampled to the training frame rate, their sensors simulated there, and are compared on
  canonical body parts (:func:`imuloco.measures.metrics.evaluate_parts`), both against
  their own ground truth and against it retargeted onto the training skeleton as the
  training clips of other rigs are (:func:`truth_on_training_rig`; the ``*_retargeted_cm``
  keys), which takes the bodies' differences out of the error.
- Cost: ``train_s`` is the wall time of ``fit`` (signal synthesis included: one bench run
  simulates each training clip once, :func:`imuloco.methods.training.cached_signals`, and
  adds the time that saved back);
  ``offline_fps`` is test frames over the wall time of ``reconstruct_signals`` (simulation and
  metrics excluded); online latency is the wall time of each ``stream().step`` over the first
  test clip (at most :data:`LATENCY_FRAMES` frames), median and 99th percentile;
  ``model_bytes`` the size of the saved model file.
- Confidence: for a method that predicts its own per-frame error
  (:class:`imuloco.methods.base.Reconstruction`), ``confidence-METHOD.npz`` holds per test
  frame the actual rms joint (or body-part) position error, the predicted one, the unreliable
  flag and the uncalibrated scores, with clip, content, fold and seed (``cross-dataset`` adds
  ``actual_retargeted_m``, the body-part error against the truth retargeted onto the training
  skeleton, whose floor is zero): what
  :mod:`imuloco.lab.confidence` checks and calibrates. Each method runs with one BLAS/OpenMP
  thread (threadpoolctl), like a single core, so that timings compare across machines'
  core counts (torch's own thread pool is the method's business).
- Path (issue 40): the path (:func:`imuloco.paths.truth.path_of_motion`) of **the animation
  the user gets** against the truth's (:mod:`imuloco.paths.metrics`): each test clip's
  simulated recording (the sensor-rate one its signals were resampled from) goes through
  :func:`imuloco.app.pipeline.animate_recording`, the function ``imuloco reconstruct`` runs
  after importing a log (calibration, the method, the fallback, the pipeline's foot pinning,
  the placement's path follower). Per clip ``path_`` + distance ratio, distance and stride
  length errors (% and m), end-point error (% of the distance walked); per motion type the
  ratio's mean and the others' mean absolute value over clips (``path_distance_ratio``,
  ``path_distance_mae_pct``, ``path_stride_mae_pct``, ``path_stride_mae_m``,
  ``path_end_point_error_pct``). The same figures of the method's raw root
  (``reconstruct_signals_full``, what these keys measured before: no path follower) are kept
  as ``path_raw_`` + the same names. The animation's pose beside them, on the frames both
  have: ``animation_mpjpe_cm`` (its first frame aligned as above) and
  ``animation_foot_skate_cm_s`` (:func:`imuloco.measures.metrics.foot_skate`, against the
  truth's ``foot_skate_gt_cm_s``), frame-weighted like the other metrics. A test example
  without a recording leaves these keys None.

Everything but the timings is deterministic: the same arguments give the same numbers.
"""

from __future__ import annotations

import inspect
import json
import re
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits
from tqdm.auto import tqdm

from imuloco.app.pipeline import animate_recording
from imuloco.core.motion import Motion, MotionDatabase
from imuloco.core.retarget import resampled
from imuloco.errors import UnknownNameError
from imuloco.io.atomic import atomic_write, atomic_write_text
from imuloco.io.database import combine, load_databases, load_sample, spread
from imuloco.lab.protocols import MOTION_TYPES, PROTOCOL_VERSION, folds
from imuloco.lab.report import write_report
from imuloco.measures import metrics
from imuloco.methods import get_method, method_class
from imuloco.methods.registry import parse_method_spec
from imuloco.methods.training import (
    TEST_SEED_OFFSET,
    Example,
    cached_signals,
    saved_seconds,
    synthesize,
)
from imuloco.paths.metrics import motion_path_errors

LATENCY_FRAMES = 300
# the reconstruction's path against the truth's, per clip (issue 40; keys path_ + these)
PATH_CLIP_KEYS = ("distance_ratio", "distance_error_pct", "stride_error_m", "stride_error_pct",
                  "end_point_error_pct")
# aggregated over clips: summary key -> clip key (the ratio's mean, the others' mean |value|)
# of the animation (``path_``) and of the method's raw root (``path_raw_``)
PATH_PREFIXES = ("path_", "path_raw_")
PATH_SUMMARY_KEYS = {f"{p}{name}": f"{p}{key}" for p in PATH_PREFIXES for name, key in (
    ("distance_ratio", "distance_ratio"), ("distance_mae_pct", "distance_error_pct"),
    ("stride_mae_pct", "stride_error_pct"), ("stride_mae_m", "stride_error_m"),
    ("end_point_error_pct", "end_point_error_pct"))}
# the animation's pose (the user's), frame-weighted as METRIC_KEYS
ANIMATION_KEYS = ("animation_mpjpe_cm", "animation_foot_skate_cm_s")


DataArg = str | Path | Sequence[str | Path] | None


def data_folders(data: DataArg) -> list[Path]:
    """Folders of a ``data`` argument: one path or several."""
    if data is None:
        return []
    return [Path(data)] if isinstance(data, (str, Path)) else [Path(d) for d in data]


def load_data(data: DataArg, limit: int | None = None, progress: bool = False,
              up: str = "auto", skip_frames: int = 0) -> MotionDatabase:
    """The clips of folder(s) ``data`` as one database on the first folder's skeleton
    (:func:`imuloco.io.database.load_databases`; ``limit`` per folder), or the bundled
    sample when ``data`` is None (``up`` and ``skip_frames`` as for
    :func:`imuloco.io.bvh.read_bvh`)."""
    if data is None:
        db = load_sample(progress=progress)
        return db.subset(spread(len(db), limit))
    return load_databases(data_folders(data), limit=limit, progress=progress, up=up,
                          skip_frames=skip_frames)


def load_cross_dataset(train: DataArg, test: DataArg, limit: int | None = None,
                       progress: bool = False, up: str = "auto", skip_frames: int = 0
                       ) -> tuple[MotionDatabase, MotionDatabase, dict[str, Motion]]:
    """``cross-dataset``'s clips (:func:`load_data`'s arguments): the training database, then
    :func:`cross_dataset_test`'s test clips and truths."""
    train_db = load_data(train, limit, progress, up, skip_frames)
    return train_db, *cross_dataset_test(train_db, test, limit, progress, up, skip_frames)


def cross_dataset_test(train_db: MotionDatabase, test: DataArg, limit: int | None = None,
                       progress: bool = False, up: str = "auto", skip_frames: int = 0
                       ) -> tuple[MotionDatabase, dict[str, Motion]]:
    """``cross-dataset``'s test clips for an already loaded training database: resampled to
    its frame rate, and each one's ground truth on its skeleton
    (:func:`truth_on_training_rig`)."""
    fps = float(train_db.clips[0].fps)
    test_db = load_data(test, limit, progress, up, skip_frames)
    test_db = MotionDatabase([resampled(c, fps) for c in test_db.clips], test_db.labels)
    return test_db, truth_on_training_rig(train_db, test_db)


def data_label(data: DataArg) -> str:
    """How records name their data: folder names joined by ``+``, or ``sample``."""
    return "+".join(f.name for f in data_folders(data)) or "sample"


def aggregate(clips: list[dict[str, Any]]) -> dict[str, Any]:
    """Frame-weighted means of per-clip metrics (nan values ignored)."""
    out: dict[str, Any] = {"n_clips": len(clips), "n_frames": int(sum(c["n_frames"]
                                                                      for c in clips))}
    w = np.array([c["n_frames"] for c in clips], dtype=np.float64)
    for key in (*metrics.METRIC_KEYS, *ANIMATION_KEYS):
        v = np.array([c.get(key) for c in clips], dtype=np.float64)  # None: nan
        ok = np.isfinite(v)
        out[key] = float(np.average(v[ok], weights=w[ok])) if ok.any() else None
    # the path's figures (issue 40): mean over clips of the ratio, mean absolute errors
    for name, key in PATH_SUMMARY_KEYS.items():
        v = np.array([c.get(key) for c in clips], dtype=np.float64)
        v = v[np.isfinite(v)]
        ratio = key.endswith("distance_ratio")
        out[name] = (float(np.mean(v if ratio else np.abs(v))) if len(v) else None)
    return out


def _latency(method, signals: np.ndarray) -> tuple[float | None, float | None, float | None]:
    """Compute time per online step (p50, p99 ms) and the stream's delay (ms of look-ahead)."""
    if not method.can_stream():
        return None, None, None
    stream = method.stream()
    times = []
    for sample in signals[:LATENCY_FRAMES]:
        t0 = time.perf_counter()
        stream.step(sample)
        times.append(time.perf_counter() - t0)
    ms = np.array(times) * 1e3
    return (float(np.percentile(ms, 50)), float(np.percentile(ms, 99)),
            stream.delay_ms(method.fps_))


def _model_bytes(method) -> int:
    with tempfile.TemporaryDirectory() as tmp:
        return method.save(Path(tmp) / "model.npz").stat().st_size


def evaluate_method(
    name: str,
    train: MotionDatabase,
    test: list[Example],
    placements: Sequence[str],
    noise: str,
    seed: int = 0,
    params: dict[str, Any] | None = None,
    progress: bool = False,
    truths: dict[str, Motion] | None = None,
) -> dict[str, Any]:
    """Fit one method and measure it on the test examples (``truths``: see :func:`measure`).

    Returns a dict with ``clips`` (per-clip metric dicts with ``name``, ``motion_type``,
    ``n_frames``), ``cost`` (train_s, offline_fps, latencies, the stream's look-ahead delay,
    model_bytes), ``per_joint`` (mean heading-frame error per joint, cm, shape (J,)) and
    ``curves`` (per-frame RMSE, cm, of each test clip by name). Test clips on another
    skeleton than the training one are measured on body parts
    (:func:`imuloco.measures.metrics.evaluate_parts`) and leave ``per_joint`` and ``curves``
    out (None / {}).
    """
    params = dict(params or {})
    if "seed" in inspect.signature(method_class(name).__init__).parameters:
        params.setdefault("seed", seed)  # a method's own seed (initial weights) follows too
    method = get_method(name, **params)
    t0, saved = time.perf_counter(), saved_seconds()
    method.fit(train, placements, noise, seed, progress=progress)
    train_s = time.perf_counter() - t0 + (saved_seconds() - saved)  # as if nothing cached
    out = measure(method, test, progress, name, truths)
    p50, p99, delay = _latency(method, test[0].signals)
    frames = sum(c["n_frames"] for c in out["clips"])
    rec_s = out.pop("reconstruct_s")
    out["cost"] = {"train_s": train_s, "offline_fps": frames / rec_s if rec_s > 0 else None,
                   "online_latency_ms_p50": p50, "online_latency_ms_p99": p99,
                   "online_delay_ms": delay, "model_bytes": _model_bytes(method)}
    return out


def measure(method, test: list[Example], progress: bool = False, name: str = "",
            truths: dict[str, Motion] | None = None) -> dict[str, Any]:
    """Reconstruct every test example with a fitted method and measure it (the module
    docstring's protocol): ``clips``, ``per_joint``, ``curves`` and ``confidence`` as
    :func:`evaluate_method` returns them, and ``reconstruct_s``, the wall time of the
    reconstructions. ``truths``: test clip name -> its ground truth on the training
    skeleton, for clips on another skeleton (:func:`truth_on_training_rig`)."""
    clips, rec_s, joint_sum, frames, curves = [], 0.0, 0.0, 0, {}
    cross = False
    confidence: list[dict[str, np.ndarray]] = []
    for ex in tqdm(test, desc=f"{name or method.name}: reconstructing", disable=not progress,
                   unit="clip"):
        gt = ex.motion
        t0 = time.perf_counter()
        full = method.reconstruct_signals_full(ex.signals)
        rec_s += time.perf_counter() - t0
        rec = full.motion
        frames += gt.num_frames
        retargeted = None  # the error against the truth on the training skeleton, per frame
        if gt.skeleton.names != rec.skeleton.names:
            cross = True
            truth = (truths or {}).get(ex.labels["name"])
            values, actual, retargeted = metrics.evaluate_parts_curves(gt, rec, truth)
        else:
            rec = metrics.align_heading(rec, gt, 0)
            values = metrics.evaluate(gt, rec)
            err = metrics.joint_errors(gt, rec) * metrics.CM
            joint_sum = joint_sum + err.sum(axis=0)
            curves[ex.labels["name"]] = np.sqrt((err[:, 1:] ** 2).mean(axis=1))
            actual = curves[ex.labels["name"]] / metrics.CM
        clips.append({"name": ex.labels["name"], "motion_type": ex.labels.get("content"),
                      "n_frames": gt.num_frames, **values, **animation_values(method, ex),
                      **_path_values(rec, gt, "path_raw_")})
        if full.error_m is not None:
            rows = _confidence_rows(full, actual, ex.labels)
            if retargeted is not None:
                rows["actual_retargeted_m"] = retargeted
            confidence.append(rows)
    return {"clips": clips, "reconstruct_s": rec_s,
            "per_joint": None if cross else joint_sum / frames, "curves": curves,
            "confidence": confidence}




def animation_values(method, ex: Example) -> dict[str, float | None]:
    """The figures of the animation ``imuloco reconstruct`` would write from ``ex``'s
    recording with the fitted ``method`` (:func:`imuloco.app.pipeline.animate_recording`):
    its path against the truth's (``path_`` + :data:`PATH_CLIP_KEYS`) and
    :data:`ANIMATION_KEYS`; all None for an example without a recording."""
    none = {**{f"path_{k}": None for k in PATH_CLIP_KEYS}, **dict.fromkeys(ANIMATION_KEYS)}
    if ex.recording is None:
        return none
    gt = ex.motion
    anim, _ = animate_recording(ex.recording, method)
    n = min(gt.num_frames, anim.num_frames)
    gt_n, anim_n = gt.slice(0, n), anim.slice(0, n)
    if gt.skeleton.names == anim.skeleton.names:
        pose = metrics.evaluate(gt_n, metrics.align_heading(anim_n, gt_n, 0))
    else:
        pose = metrics.evaluate_parts(gt_n, anim_n)
    return {**_path_values(anim, gt), "animation_mpjpe_cm": pose["mpjpe_cm"],
            "animation_foot_skate_cm_s": pose["foot_skate_cm_s"]}


def _path_values(rec: Motion, gt: Motion, prefix: str = "path_") -> dict[str, float | None]:
    """The reconstruction's path against the truth's (:func:`imuloco.paths.metrics.
    path_errors`), keys ``prefix`` + :data:`PATH_CLIP_KEYS` (None where undefined: a clip
    without strides, or too short for gait phases)."""
    try:
        errs = motion_path_errors(rec, gt)
    except (ValueError, KeyError):  # a clip under two frames, a skeleton without feet
        return {f"{prefix}{k}": None for k in PATH_CLIP_KEYS}
    return {f"{prefix}{k}": (float(errs[k]) if np.isfinite(errs[k]) else None)
            for k in PATH_CLIP_KEYS}


def _confidence_rows(full, actual: np.ndarray, labels: dict[str, Any]) -> dict[str, np.ndarray]:
    """Per-frame confidence rows of one test clip (see the module docstring)."""
    n = len(actual)
    rows = {"actual_m": actual, "error_m": np.asarray(full.error_m, float),
            "unreliable": (np.zeros(n, bool) if full.unreliable is None
                           else np.asarray(full.unreliable, bool)),
            "clip": np.full(n, labels["name"]), "content": np.full(n, labels.get("content") or "")}
    rows.update({f"score_{k}": np.asarray(v, float) for k, v in (full.scores or {}).items()})
    return rows


def run_bench(
    methods: Sequence[str],
    split_name: str = "random-clips",
    noise: str = "phone",
    placements: Sequence[str] = ("right_ankle",),
    data: DataArg = None,
    out: str | Path | None = None,
    limit: int | None = None,
    seed: int = 0,
    progress: bool = False,
    seeds: int = 1,
    train: DataArg = None,
    test: DataArg = None,
    up: str = "auto",
    skip_frames: int = 0,
    only_folds: Sequence[str] | None = None,
) -> list[dict[str, Any]]:
    """Run the benchmark protocol and return its records (one per method x motion type).

    Parameters
    ----------
    methods : registry names, each optionally with hyperparameters as
        ``NAME[key=value;key=value]`` (see :func:`imuloco.methods.registry.parse_method_spec`); records keep the spec
        as their ``method``.
    split_name : a protocol of :data:`imuloco.lab.protocols.SPLITS`.
    noise : sensor noise preset for training and test signals.
    placements : sensor placement presets.
    data : folder(s) of clips (None: the bundled sample); not for ``cross-dataset``.
    out : folder for ``results.json``, ``per_clip.json`` and ``results.md`` (+ plots); None
        writes nothing.
    limit : read at most this many clips (per folder, before the split), for quick runs.
    seed : first training seed; test recordings use ``seed + TEST_SEED_OFFSET``.
    seeds : number of training seeds (see the module docstring).
    train, test : the folders of ``cross-dataset`` (training: one or several; test: one).
    up, skip_frames : how motion files are read (see :func:`imuloco.io.bvh.read_bvh`).
    only_folds : run only these folds of ``heldout-contents`` or ``heldout-actions``
        (left-out contents).
    """
    specs = {m: parse_method_spec(m) for m in methods}
    for name, params in specs.values():  # fail before any work on an unknown or uninstalled
        get_method(name, **params)  # method, or a parameter it does not take or cannot use
    if seeds < 1:
        raise ValueError(f"seeds must be at least 1, got {seeds}")
    placements = list(placements)
    if split_name == "cross-dataset":
        if not data_folders(train) or len(data_folders(test)) != 1:
            raise UnknownNameError("cross-dataset needs training folder(s) and one test folder "
                           "(--train DIR[,DIR] --test DIR)")
        train_db, test_db, truths = load_cross_dataset(train, test, limit, progress, up,
                                                       skip_frames)
        protocol = [("all", train_db, test_db)]
        label = f"{data_label(train)} -> {data_label(test)}"
    else:
        if train is not None or test is not None:
            raise UnknownNameError("--train/--test are for --split cross-dataset; use --data")
        protocol = folds(load_data(data, limit, progress, up, skip_frames), split_name)
        truths = None
        if only_folds:
            unknown = sorted(set(only_folds) - {f for f, _, _ in protocol})
            if unknown:
                raise UnknownNameError(f"no fold {unknown} in {split_name}; folds: "
                                       f"{[f for f, _, _ in protocol]}")
            protocol = [p for p in protocol if p[0] in only_folds]
        label = data_label(data)
    header = {"split": split_name, "noise": noise, "placements": placements,
              "protocol_version": PROTOCOL_VERSION, "seed": seed, "data": label,
              "seeds": list(range(seed, seed + seeds)), "folds": [f for f, _, _ in protocol]}
    runs: dict[str, list[dict[str, Any]]] = {m: [] for m in methods}  # per seed
    all_test: list[Example] = []
    with cached_signals():
        for fold, train_db, test_db in protocol:
            all_test += _run_fold(fold, train_db, test_db, methods, specs, runs, placements,
                                  noise, seed, seeds, progress, truths)

    records = []
    for name in methods:
        clips0 = runs[name][0]["clips"]
        types = [t for t in MOTION_TYPES if any(c["motion_type"] == t for c in clips0)]
        types += sorted({c["motion_type"] for c in clips0} - set(types) - {None})
        for mtype in [*types, "all"]:
            per_seed = [aggregate([c for c in r["clips"]
                                    if mtype == "all" or c["motion_type"] == mtype])
                        for r in runs[name]]
            costs = [c for r in runs[name] for c in r["costs"]]
            records.append({"method": name, **header, "motion_type": mtype,
                            **_over_seeds(per_seed), **_mean_costs(costs)})
    details = {m: {"clips": r[0]["clips"],
                   "per_joint": (None if any(p is None for p in r[0]["per_joint"])
                                 else np.mean(r[0]["per_joint"], axis=0)),
                   "curves": r[0]["curves"],
                   "confidence": [rows for run in r for rows in run["confidence"]]}
               for m, r in runs.items()}
    if out is not None:
        write_results(records, details, all_test, Path(out))
    return records


def truth_on_training_rig(train: MotionDatabase, test: MotionDatabase) -> dict[str, Motion]:
    """Test clip name -> its ground truth moved onto the training skeleton as a training
    clip of its rig would be (:func:`imuloco.io.database.combine`): what a perfect
    reconstruction on that skeleton would be."""
    moved = combine([train, test]).clips[len(train):]
    return {lab["name"]: m for lab, m in zip(test.labels, moved)}


def _run_fold(fold: str, train_db: MotionDatabase, test_db: MotionDatabase,
              methods: Sequence[str], specs: dict[str, tuple[str, dict[str, Any]]],
              runs: dict[str, list[dict[str, Any]]], placements: list[str], noise: str,
              seed: int, seeds: int, progress: bool,
              truths: dict[str, Motion] | None = None) -> list[Example]:
    """Fit every method with every seed on one fold; add their results to ``runs``."""
    test_ex = synthesize(test_db, placements, noise, seed + TEST_SEED_OFFSET, progress=progress)
    for name in tqdm(methods, desc=f"methods ({fold})", disable=not progress):
        for k in range(seeds):
            with threadpool_limits(limits=1):
                res = evaluate_method(specs[name][0], train_db, test_ex, placements, noise,
                                      seed + k, params=specs[name][1], progress=progress,
                                      truths=truths)
            for c in res["clips"]:
                c["fold"] = fold
            for rows in res["confidence"]:
                n = len(rows["actual_m"])
                rows.update(fold=np.full(n, fold), seed=np.full(n, seed + k))
            if len(runs[name]) <= k:
                runs[name].append({"clips": [], "costs": [], "per_joint": [], "curves": {},
                                   "confidence": []})
            run = runs[name][k]
            run["confidence"] += res["confidence"]
            run["clips"] += res["clips"]
            run["costs"].append(res["cost"])
            run["per_joint"].append(res["per_joint"])
            run["curves"].update(res["curves"])
    return test_ex


def _over_seeds(per_seed: list[dict[str, Any]]) -> dict[str, Any]:
    """Mean of each metric over seeds, its spread (``<key>_std``, ddof 1) and the runs'
    MPJPE; counts from the first run (the test clips are the same)."""
    out = dict(per_seed[0])
    for key in (*metrics.METRIC_KEYS, *ANIMATION_KEYS, *PATH_SUMMARY_KEYS):
        v = [r[key] for r in per_seed if r.get(key) is not None]
        out[key] = float(np.mean(v)) if v else None
        out[f"{key}_std"] = float(np.std(v, ddof=1)) if len(v) > 1 else None
    out["mpjpe_cm_per_seed"] = [r["mpjpe_cm"] for r in per_seed]
    return out


def _mean_costs(costs: list[dict[str, Any]]) -> dict[str, Any]:
    """Costs averaged over folds and seeds (None stays None)."""
    out = {}
    for key in costs[0]:
        v = [c[key] for c in costs if c[key] is not None]
        out[key] = None if not v else (int(np.mean(v)) if key == "model_bytes"
                                       else float(np.mean(v)))
    return out


def slug(spec: str) -> str:
    """A method spec as a file-name part: ``learned[lag=4]`` -> ``learned_lag=4_``."""
    return re.sub(r"[^A-Za-z0-9=.,-]+", "_", spec)


def write_results(records: list[dict[str, Any]], details: dict[str, dict[str, Any]],
                  test: list[Example], out: Path) -> None:
    """``results.json`` (the records), ``per_clip.json`` and ``results.md`` with its plots."""
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "results.json", json.dumps(records, indent=1) + "\n")
    per_clip = [{"method": m, **{k: (None if isinstance(v, float) and not np.isfinite(v) else v)
                                  for k, v in c.items()}}
                for m, d in details.items() for c in d["clips"]]
    atomic_write_text(out / "per_clip.json", json.dumps(per_clip, indent=1) + "\n")
    for m, d in details.items():
        if d.get("confidence"):
            rows = d["confidence"]
            arrays = {k: np.concatenate([r[k] for r in rows]) for k in rows[0]}
            with atomic_write(out / f"confidence-{slug(m)}.npz", "wb") as f:
                np.savez_compressed(f, **arrays)
    skeleton = test[0].motion.skeleton
    clip = test[0].labels["name"]
    per_joint = {m: d["per_joint"] for m, d in details.items() if d["per_joint"] is not None}
    curves = {m: d["curves"][clip] for m, d in details.items() if clip in d["curves"]}
    write_report(records, out, per_joint=per_joint or None, joint_names=skeleton.names,
                 curves=curves or None, curve_clip=clip, fps=test[0].motion.fps)
