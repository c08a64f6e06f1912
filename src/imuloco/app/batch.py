"""Many recordings at once on Dask: one walker per phone log, resumable, with study tables.

:func:`run_batch` reconstructs every recording with one model on a Dask cluster: by default a
``distributed.LocalCluster`` of ``jobs`` worker processes started for the run, or an existing
cluster at ``scheduler`` (started with ``dask scheduler`` and ``dask worker ADDRESS``; its
workers read the recordings and write ``out_dir`` at the paths given here, so on several
machines these live on a shared file system). Per recording a worker writes ``NAME.bvh`` and
``NAME.json`` (the reconstruction report: import, calibration, gait parameters, plausibility
checks, plus ``strides`` and ``batch``: recording, model hash, placement, height); then this
process writes ``summary.csv`` and ``summary.json`` (one row per walker: cadence, speed, step
and stride length, ..., height), ``walkers.parquet`` (the same rows with placement and model,
:data:`WALKER_FIELDS`, with the method's mean predicted error and flagged share and a shank
sensor's swings) and
``strides.parquet`` (one row per stride, ``walker`` then
:data:`imuloco.measures.strides.STRIDE_FIELDS`). A walkers file
(:mod:`imuloco.app.walkers`) gives each walker a height and the study's own columns.

- The model travels as its file's bytes, scattered once to the workers and loaded once per
  worker process (cached by SHA-256): never a pickled method object.
- Every file is written atomically (:func:`imuloco.io.atomic.atomic_write`), the JSON last: a
  recording is complete when its JSON names the same recording, model, unit, height and
  placement. A re-run skips complete recordings (``force`` redoes them), redoes a walker
  whose height changed and refuses to replace another job's outputs.
- One run at a time writes ``out_dir`` (:class:`imuloco.io.folderlock.FolderLock`: a second
  gets an error naming the first's host, pid and start); temporary files of a run that was
  killed are removed (:func:`imuloco.io.atomic.clean_stale`). A recording's BVH and JSON are
  one :class:`imuloco.io.atomic.OutputSet`, the JSON naming the BVH's SHA-256: a BVH beside
  another run's report is redone, not taken as complete.
- Only regular files and folders are recordings (a FIFO named ``.csv`` hung the run); paths
  are resolved and de-duplicated, and ``**`` does not follow links to folders (a link loop made
  one recording into 41 walkers). A recording with no result after ``timeout_s`` (default
  :data:`TIMEOUT_S`) becomes an error row (its worker thread is abandoned, not killed:
  Python cannot stop a thread, and a worker process is the cluster's to restart).
- A recording that fails becomes a row with status ``error`` and its error; the others go on.
  A task whose worker dies is rescheduled by Dask (up to ``distributed.scheduler.allowed-
  failures`` times), one that raises outside the reconstruction is retried ``retries`` times.
"""

from __future__ import annotations

import contextlib
import contextvars
import csv
import functools
import glob as globmod
import hashlib
import json
import logging
import os
import tempfile
import threading
import time
import uuid
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from tqdm.auto import tqdm

from imuloco.app.outputs import Outputs, write_outputs
from imuloco.app.pipeline import choose_method, load_rig, reconstruct_file, require_extras
from imuloco.app.walkers import Walkers, read_walkers
from imuloco.core.rigs import DEFAULT_RIG, check_rig_name
from imuloco.errors import ImulocoError, InputError, MissingExtraError, OutputExistsError
from imuloco.io.atomic import atomic_write, check_output, clean_stale, sha256_file
from imuloco.io.folderlock import FolderLock
from imuloco.io.sensorlog import export_members
from imuloco.measures.strides import STRIDE_FIELDS
from imuloco.methods import load_model
from imuloco.methods.modelfile import save_model
from imuloco.sensors.reallog import realworld_accelerometer, recording_name

log = logging.getLogger(__name__)

# summary columns after name and status, taken from the report's gait parameters
GAIT_COLUMNS = ("cadence_spm", "cadence_rhythm_spm", "speed_mps", "step_length_m",
                "stride_length_m", "steps", "stance_pct", "double_support_pct")
COLUMNS = ("name", "recording", "status", "frames", "duration_s", *GAIT_COLUMNS,
           "signal_cadence_spm", "seconds", "error", "height_m")  # summary.csv
# + the method's confidence over the recording (metres of predicted rms joint position error,
# share of frames flagged; None for methods without one)
# and how far each reconstructed shank swings in a stride, and a shank sensor's signal (degrees;
# None for other sensors' signals and in reports of older versions)
SWING_FIELDS = ("signal_swing_deg", "left_shank_swing_deg", "right_shank_swing_deg")
WALKER_FIELDS = (*COLUMNS, "placement", "method", "model", "model_sha256",
                 "mean_error_m", "unreliable_fraction", *SWING_FIELDS)
_STRINGS = {"name", "recording", "status", "error", "placement", "method", "model",
            "model_sha256", "walker", "foot"}
_INTEGERS = {"frames", "steps"}
RESERVED_NAMES = ("summary",)  # summary.json is the batch's: no recording's NAME.json
OUTPUT_TABLES = ("summary.csv", "summary.json", "walkers.parquet", "strides.parquet")
CONNECT_TIMEOUT_S = 30.0  # waiting for a scheduler, then for its first worker
# a recording's time limit: an hour-long log takes about a minute (docs/results/batch), so an
# hour means stuck (a file that never ends, a pathological input), not slow
TIMEOUT_S = 3600.0
# no dashboard, and the scheduler's HTTP server (health, metrics) on a free port, not on 8787,
# which another cluster on the machine may hold
LOCAL_CLUSTER = {"dashboard_address": None, "scheduler_kwargs": {"dashboard_address": ":0"}}


def own_output(path: Path, out_dir: str | Path | None) -> bool:
    """Whether ``path`` is one of a batch's outputs in ``out_dir`` (its tables, a walker's
    NAME.bvh or NAME.json), which a glob such as ``'*/*.csv'`` matches on a re-run."""
    if out_dir is None:
        return False
    folder = Path(os.path.normpath(Path(out_dir).absolute()))
    path = Path(os.path.normpath(path.absolute()))
    return path.parent == folder and (path.name in OUTPUT_TABLES
                                      or path.suffix.lower() in (".bvh", ".json"))


def find_recordings(paths: Sequence[str | Path] = (), patterns: Sequence[str] = (),
                    out_dir: str | Path | None = None) -> list[Path]:
    """The recordings named and matched by glob ``patterns`` (``**`` recurses), sorted within
    each pattern, duplicates dropped, in the order given. A file of an unzipped Sensor Logger
    or phyphox export (``study/*/*.csv``, ``study/**/*.csv``: also phyphox's ``meta/``) is
    its folder, which reads the export: one walker named after it. A RealWorld gyroscope file
    whose ``acc_`` file is among them is dropped too: that file reads the pair, one walker.
    The batch's own outputs in ``out_dir`` (:func:`own_output`) are never recordings."""
    found: list[Path] = [Path(p) for p in paths]
    for p in found:
        if p.exists() and not (p.is_file() or p.is_dir()):
            raise InputError(f"{p}: not a regular file or folder (a FIFO, a device, ...); "
                             "expected a sensor log")
    for pattern in patterns:
        matches = [m for m in _glob(str(pattern)) if m.is_file() or m.is_dir()]
        if not matches:
            log.warning("no recording matches %r", pattern)
        found += [Path(m) for m in matches]
    own = [p for p in found if own_output(p, out_dir)]
    if own:
        log.warning("left out %d file(s) this batch writes in %s (%s)", len(own), out_dir,
                    ", ".join(sorted({p.name for p in own})[:3]))
        found = [p for p in found if not own_output(p, out_dir)]
    members: dict[Path, set[str]] = {}  # per folder: the files of its app export

    def walker(p: Path) -> Path:
        """The path that reads ``p``'s walker: ``p``, or its export's folder."""
        if p.suffix.lower() != ".csv" or not p.is_file():
            return p
        path = Path(os.path.normpath(p.absolute()))  # folders named, also for a bare name
        for folder in path.parents[:2]:  # an export's table, or a file of its meta/ folder
            if folder not in members:
                members[folder] = export_members(folder)
            if path.relative_to(folder).as_posix() in members[folder]:
                return folder
        return p

    def key(p: Path) -> str:
        return os.path.realpath(p)  # one file reached through links is one walker

    found = [walker(p) for p in found]
    keys = {key(p) for p in found}
    seen, out = set(), []
    for p in found:
        acc = realworld_accelerometer(p)
        if key(p) not in seen and (acc is None or key(acc) not in keys):
            seen.add(key(p))
            out.append(p)
    return out


def _glob(pattern: str) -> list[Path]:
    """The paths matching a glob ``pattern`` (``**`` recurses), sorted, as ``glob.glob``
    finds them but without following links to folders under ``**`` (``glob`` does: a link
    loop repeats each file 40 times, two loops in one folder 2**40 times); hidden names are
    matched only by a pattern that says so. (pathlib's ``glob`` before Python 3.13 does not
    follow them under ``**``; it takes a relative pattern below a folder.)"""
    parts = Path(pattern).parts
    k = next((i for i, part in enumerate(parts) if globmod.has_magic(part)), len(parts))
    base, rest = Path(*parts[:k]) if k else Path("."), parts[k:]
    if not rest:
        return [base] if base.exists() else []
    if rest[-1] == "**":  # glob's "**" at the end also matches files; pathlib's folders only
        rest = (*rest, "*")
    hidden = [part.startswith(".") for part in rest]
    out = []
    for p in base.glob(str(Path(*rest))):
        names = p.relative_to(base).parts
        if len(names) == len(rest) and any(n.startswith(".") and not h
                                           for n, h in zip(names, hidden)):
            continue
        if "**" in rest and any(n.startswith(".") for n in names):
            continue  # glob.glob leaves hidden files and folders out of **
        out.append(p if k else Path(os.path.relpath(p)))
    return sorted(out)


def output_names(paths: Sequence[Path]) -> list[str]:
    """A distinct output name per recording: its own (a file's stem, a folder's whole name:
    an export's ``alice.day1``), with its folder's name (then a number) prepended where names
    repeat (``walker1/log.csv``, ``walker2/log.csv``) or are the batch's own
    (:data:`RESERVED_NAMES`). Names differ also where the file system ignores case
    (``a/Alice.csv``, ``b/alice.csv``: ``a_Alice``, ``b_alice``), so no recording's outputs
    replace another's."""
    full = [Path(os.path.normpath(p.absolute())) for p in paths]  # "." and bare names named
    own = [recording_name(p) for p in full]
    folded = [n.casefold() for n in own]
    names = [f"{p.parent.name}_{n}" if folded.count(f) > 1 or f in RESERVED_NAMES else n
             for p, n, f in zip(full, own, folded)]
    out, used = [], set(RESERVED_NAMES)
    for n in names:
        cand, k = n, 2
        while cand.casefold() in used:
            cand, k = f"{n}_{k}", k + 1
        used.add(cand.casefold())
        out.append(cand)
    return out


# ---- on a worker --------------------------------------------------------------------------
_MODELS: dict[str, Any] = {}  # SHA-256 of a model file -> its fitted method, per process
_MODELS_LOCK = threading.Lock()


def worker_model(sha256: str, data: bytes):
    """The fitted method of the model file ``data`` (bytes), loaded once per process."""
    with _MODELS_LOCK:
        if sha256 not in _MODELS:
            with tempfile.TemporaryDirectory(prefix="imuloco-model-") as tmp:
                path = Path(tmp) / "model.npz"
                path.write_bytes(data)
                _MODELS.clear()  # one job's model at a time
                _MODELS[sha256] = load_model(path)
        return _MODELS[sha256]


def reconstruct_one(recording: str, out_dir: str, name: str, model_sha256: str, model: bytes,
                    placement: str = "right_ankle", fmt: str = "auto", calibrate: bool = True,
                    platform: str | None = None, height_m: float | None = None,
                    unit: str = "cm", skeleton: str | None = None,
                    timeout_s: float | None = None, rig: str | None = DEFAULT_RIG,
                    columns: dict[str, str] | None = None) -> dict[str, Any]:
    """Reconstruct one recording (a path read here), write ``NAME.bvh`` (lengths in ``unit``)
    (on rig preset ``rig``) and ``NAME.json`` as one set, the JSON naming the BVH's SHA-256.

    Returns ``{"row": ..., "strides": [...]}`` (see :func:`walker_rows`); errors are caught and
    reported in the row, as is no result after ``timeout_s`` seconds (None: no limit)."""
    args = (recording, out_dir, name, model_sha256, model, placement, fmt, calibrate, platform,
            height_m, unit, skeleton, rig, columns)
    if timeout_s is None:
        return _reconstruct_one(*args)
    t0, result, context = time.perf_counter(), [], contextvars.copy_context()  # Dask's worker
    thread = threading.Thread(target=lambda: result.append(context.run(_reconstruct_one, *args)),
                              name=f"imuloco-batch-{name}", daemon=True)
    thread.start()
    thread.join(timeout_s)
    if result:
        return result[0]
    log.warning("%s: no result after %g s: abandoned", recording, timeout_s)
    error = TimeoutError(f"no result after {timeout_s:g} s (the time limit, --timeout)")
    return {"row": error_row(name, recording, error, time.perf_counter() - t0), "strides": []}


def _reconstruct_one(recording: str, out_dir: str, name: str, model_sha256: str, model: bytes,
                     placement: str, fmt: str, calibrate: bool, platform: str | None,
                     height_m: float | None, unit: str, skeleton: str | None,
                     rig: str | None, columns: dict[str, str] | None
                     ) -> dict[str, Any]:
    """:func:`reconstruct_one` without its time limit."""
    t0 = time.perf_counter()
    try:
        fitted = worker_model(model_sha256, model)
        with _warnings_logged() as warned:
            motion, recon = reconstruct_file(recording, placement=placement, fmt=fmt,
                                             calibrate=calibrate, fitted=fitted,
                                             platform=platform, skeleton=skeleton,
                                             height=height_m, columns=columns)
        recon.warnings = [w.getMessage() for w in warned]
        recon.seconds = round(time.perf_counter() - t0, 3)
        recon.batch = {"recording": recording, "model_sha256": model_sha256,
                       "placement": placement, "height_m": height_m, "unit": unit,
                       "rig": rig}
        out = Path(out_dir)
        # atomic, the JSON last: it marks the outputs complete
        write_outputs(Outputs(out / f"{name}.bvh", out / f"{name}.json", unit=unit, rig=rig),
                      recon,
                      motion)
        report = recon.to_json()
    except Exception as e:  # noqa: BLE001 - one bad recording must not stop the batch
        log.warning("%s: %s: %s", recording, type(e).__name__, e)
        return {"row": error_row(name, recording, e, time.perf_counter() - t0), "strides": []}
    row, strides = walker_rows(name, report)
    return {"row": row, "strides": strides,
            "warnings": [{"kind": str(w.msg), "text": w.getMessage()} for w in warned]}


class _Records(logging.Handler):
    """Keeps the warnings one thread logs (a worker's task, whose log the user never sees)."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.thread, self.records = threading.get_ident(), []

    def emit(self, record: logging.LogRecord) -> None:
        if record.thread == self.thread:
            self.records.append(record)


@contextlib.contextmanager
def _warnings_logged():
    """The warnings logged by this thread in the block: a list of LogRecords, which the
    batch relays to its terminal and writes into the walker's report (``warnings``)."""
    handler = _Records()
    root = logging.getLogger()
    root.addHandler(handler)
    try:
        yield handler.records
    finally:
        root.removeHandler(handler)


# ---- rows ---------------------------------------------------------------------------------
def walker_rows(name: str, report: dict[str, Any]) -> tuple[dict, list[dict]]:
    """The walker's row (:data:`WALKER_FIELDS` but the job's ``method`` and ``model``) and its
    stride rows from a report written by :func:`reconstruct_one`."""
    gait, batch = report["gait"], report["batch"]
    confidence = report.get("confidence") or {}  # none in reports of older versions
    row = {"name": name, "recording": batch["recording"], "status": "ok",
           "frames": report["motion"]["frames"], "duration_s": report["motion"]["duration_s"],
           **{k: gait.get(k) for k in GAIT_COLUMNS},
           "signal_cadence_spm": report["signal_cadence_spm"], "seconds": report["seconds"],
           "error": "", "height_m": batch["height_m"], "placement": batch["placement"],
           "model_sha256": batch["model_sha256"],
           "mean_error_m": confidence.get("mean_error_m"),
           "unreliable_fraction": confidence.get("unreliable_fraction"),
           "signal_swing_deg": report.get("signal_swing_deg"),
           **{k: report["plausibility"].get(k) for k in SWING_FIELDS[1:]}}
    return row, [{"walker": name, **s} for s in report["strides"]]


def error_row(name: str, recording: str, error: BaseException, seconds: float) -> dict:
    """The row of a recording that failed."""
    return {"name": name, "recording": recording, "status": "error",
            "error": f"{type(error).__name__}: {error}", "seconds": round(seconds, 3)}


def _complete_report(out: Path, name: str, recording: str, sha256: str, unit: str = "cm",
                     height_m: float | None = None, placement: str | None = None,
                     rig: str | None = DEFAULT_RIG) -> dict | None | bool:
    """``NAME.json`` when it completes this recording with this model, BVH unit, height,
    placement (``None``: any placement) and rig preset; ``None`` when there is no JSON or it
    has another height or rig, or does not name the BVH beside it by its SHA-256 (to do: a run
    killed between writing the two, or a report of an older version);
    ``False`` when outputs of another recording, model, unit, placement or program are
    there."""
    path = out / f"{name}.json"
    if not path.exists():
        return None
    try:
        report = json.loads(path.read_text())
        batch = report["batch"]
        same = (batch["recording"] == recording and batch["model_sha256"] == sha256
                and batch.get("unit", "cm") == unit
                and placement in (None, batch.get("placement", placement))
                and (out / f"{name}.bvh").is_file())
        if same and batch.get("bvh_sha256") != sha256_file(out / f"{name}.bvh"):
            return None
    except (OSError, ValueError, KeyError, TypeError):
        return False
    redo = batch.get("height_m") != height_m or batch.get("rig", "model") != rig
    return False if not same else None if redo else report


def _schema(fields: Sequence[str], extra: Sequence = ()):
    """The columns ``fields`` typed, then the pyarrow fields ``extra``."""
    import pyarrow as pa  # the [dist] extra's

    return pa.schema([*((f, pa.string() if f in _STRINGS else
                         pa.int64() if f in _INTEGERS else pa.float64()) for f in fields),
                      *extra])


def stride_table(strides: list[dict]):
    """Stride rows as a pyarrow Table: columnar, so a study's millions of strides fit in memory
    (about 100 bytes a stride, against about 1 kB as dicts)."""
    import pyarrow as pa  # the [dist] extra's

    return pa.Table.from_pylist(strides, schema=_schema(("walker", *STRIDE_FIELDS)))


def write_tables(out: Path, rows: list[dict], strides: list, inputs: Sequence[Path] = (),
                 extra: Sequence = ()) -> list[Path]:
    """Write ``summary.csv``, ``walkers.parquet`` and ``strides.parquet`` (from the walkers'
    :func:`stride_table`, in order) atomically; ``extra``: pyarrow fields of the study's own
    columns (:class:`imuloco.app.walkers.Walkers`) that follow batch's in the rows."""
    import pyarrow as pa  # the [dist] extra's
    import pyarrow.parquet as pq

    def whole(v: Any) -> Any:
        return None if v is None else int(v)

    paths = [check_output(out / n, force=True, inputs=inputs)
             for n in ("summary.csv", "walkers.parquet", "strides.parquet")]
    with atomic_write(paths[0], "w") as f:
        writer = csv.DictWriter(f, fieldnames=[*COLUMNS, *(x.name for x in extra)],
                                extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    walkers = [{**r, **{k: whole(r.get(k)) for k in _INTEGERS}} for r in rows]
    tables = (pa.Table.from_pylist(walkers, schema=_schema(WALKER_FIELDS, extra)),
              pa.concat_tables([stride_table([]), *strides]))
    for path, table in zip(paths[1:], tables):
        with atomic_write(path, "wb") as f:
            pq.write_table(table, f)
    return paths


# ---- the job ------------------------------------------------------------------------------
@contextlib.contextmanager
def dask_client(scheduler=None, jobs: int | None = None):
    """A ``distributed.Client``: on ``scheduler`` (an address, or a Client used as it is) or on
    a LocalCluster of ``jobs`` single-threaded worker processes (``None``/``-1``: one per CPU)
    closed afterwards."""
    try:
        from distributed import Client, LocalCluster  # the [dist] extra's
    except ImportError:
        raise MissingExtraError("batch", "distributed", "dist") from None
    if isinstance(scheduler, Client):
        yield scheduler
        return
    if scheduler:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
        except (OSError, ValueError, TypeError) as e:
            raise ImulocoError(f"cannot reach the Dask scheduler at {scheduler!r}: {e}; start "
                               "one with `dask scheduler` (see the README)") from None
        with client:
            try:
                client.wait_for_workers(1, timeout=CONNECT_TIMEOUT_S)
            except TimeoutError:
                raise ImulocoError(f"the Dask scheduler at {scheduler} has no worker after "
                                   f"{CONNECT_TIMEOUT_S:.0f} s; start one with `dask worker "
                                   f"{scheduler}`") from None
            yield client
        return
    n = len(os.sched_getaffinity(0)) if jobs in (None, -1) else int(jobs)
    if n < 1:
        raise ValueError(f"jobs must be a positive number of workers or -1, got {jobs}")
    with LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                      **LOCAL_CLUSTER) as cluster, Client(cluster) as client:
        yield client


def _one_run_at_a_time(run: Callable[..., dict[str, Any]]) -> Callable[..., dict[str, Any]]:
    """``run(recordings, out_dir, ...)`` holding ``out_dir``'s :class:`FolderLock` (a second
    run is refused before any work), after removing a killed run's temporaries there."""
    @functools.wraps(run)
    def locked(recordings: Sequence[str | Path], out_dir: str | Path, *args: Any,
               **kwargs: Any) -> dict[str, Any]:
        out = Path(out_dir).absolute()
        made = not out.exists()
        out.mkdir(parents=True, exist_ok=True)
        try:
            with FolderLock(out):
                clean_stale(out)
                return run(recordings, out_dir, *args, **kwargs)
        except BaseException:
            if made and not any(out.iterdir()):  # refused before any work: no folder left
                out.rmdir()
            raise
    return locked


@_one_run_at_a_time
def run_batch(recordings: Sequence[str | Path], out_dir: str | Path, jobs: int | None = None,
              model: str | Path | None = None, method: str | None = None,
              placement: str = "right_ankle", fmt: str = "auto", calibrate: bool = True,
              force: bool = False, progress: bool = False, fitted=None, scheduler=None,
              platform: str | None = None, height_m: float | None = None, retries: int = 2,
              unit: str = "cm", skeleton: str | Path | None = None,
              walkers: str | Path | None = None, timeout_s: float | None = TIMEOUT_S,
              rig: str | None = DEFAULT_RIG, columns: dict[str, str] | None = None
              ) -> dict[str, Any]:
    """Reconstruct every recording into ``out_dir`` on Dask (see the module docstring).

    Parameters
    ----------
    recordings : log files (see :func:`imuloco.sensors.reallog.read_log`), one walker each.
    out_dir : folder for the outputs (created).
    jobs : workers of the local cluster (``None`` or ``-1``: one per CPU).
    model, method, placement : the model, as :func:`imuloco.app.pipeline.choose_method` picks it.
    fmt, calibrate, platform : see :func:`imuloco.app.pipeline.reconstruct_file`; the
        report's ``strides`` are the estimator's for the placement (a foot sensor's own).
    force : redo recordings whose outputs are complete, replace another job's outputs.
    progress : a progress bar (tqdm) on stderr.
    fitted : an already fitted method (skips the choice).
    scheduler : address of an existing Dask scheduler (``tcp://host:8786``) or a
        ``distributed.Client`` to use instead of a local cluster.
    height_m : the walkers' height in metres, recorded in the tables (``None``: not given);
        the default of those the walkers file gives none.
    retries : Dask retries of a task that raises outside the reconstruction.
    unit : length unit of the BVH files (``cm`` or ``m``; see :func:`imuloco.io.bvh.write_bvh`).
    skeleton : a motion file of the user's rig: every BVH comes out on it (checked before
        starting; see :func:`imuloco.app.pipeline.onto_rig`).
    walkers : a CSV of the walkers' heights and the study's own columns, by output name, that
        may hold walkers of other batches (:func:`imuloco.app.walkers.read_walkers`; read
        before starting).
    timeout_s : a recording's time limit in seconds (None: none); one with no result by then
        is an error row.
    rig : the rig preset of the BVH files (:func:`imuloco.app.export.write_reconstruction`;
        None with ``skeleton``).
    columns : a CSV's own names of the generic log's columns
        (:func:`imuloco.io.sensorlog.parse_columns`), for every recording.

    Returns
    -------
    The summary (also written to ``summary.json``): ``model``, ``method``, ``model_sha256``,
    ``jobs`` (workers), ``scheduler``, ``model_seconds`` (choosing the model), ``seconds``
    (reconstructing, from the cluster ready to the last result), ``done``, ``skipped``
    (complete from an earlier run), ``ok`` (done + skipped), ``failed``, ``frames``
    (reconstructed), ``strides`` and ``recordings`` (rows in input order).
    """
    require_extras(placement)  # on this machine, before starting any worker
    paths = [Path(p) for p in recordings]
    if not paths:
        raise ValueError("no recordings given")
    names = output_names(paths)
    study = Walkers() if walkers is None else read_walkers(walkers, names, WALKER_FIELDS)
    heights = {n: study.heights.get(n, height_m) for n in names}
    inputs = [*paths, *([] if walkers is None else [Path(walkers)])]
    recs = [os.path.normpath(p.absolute()) for p in paths]
    out = Path(out_dir).absolute()
    if skeleton is not None:
        load_rig(skeleton)  # refuse a rig that cannot be mapped before any work
        rig = None  # the BVHs are on the user's rig
    elif rig is not None:
        check_rig_name(rig)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    if fitted is None:
        fitted, note = choose_method(method, model, placement, progress=progress)
    else:
        note = f"given fitted method {fitted.name!r}"
    with tempfile.TemporaryDirectory(prefix="imuloco-batch-") as tmp:
        # without its training's time: a model fitted on the fly (``--method mean``) resumes
        fitted.check_fitted()
        blob = save_model(fitted, Path(tmp) / "model.npz", timing=False).read_bytes()
    sha = hashlib.sha256(blob).hexdigest()
    model_seconds = time.perf_counter() - t0

    reports = {n: _complete_report(out, n, r, sha, unit, heights[n], placement, rig)
               for n, r in zip(names, recs)}
    foreign = [str(out / f"{n}.json") for n, rep in reports.items() if rep is False]
    if foreign and not force:
        raise OutputExistsError(f"{', '.join(foreign[:3])}{' ...' if len(foreign) > 3 else ''}"
                                " hold(s) another recording's, model's, unit's or "
                                "placement's outputs; pass --force "
                                "(force=True) to replace them or choose another --out")
    rows: dict[str, dict] = {}
    strides: dict[str, Any] = {}  # pyarrow Tables
    for n, rep in reports.items():
        if rep and not force:
            rows[n], table = walker_rows(n, rep)
            strides[n] = stride_table(table)
    skipped = len(rows)
    todo = [(n, r) for n, r in zip(names, recs) if n not in rows]
    for n, _ in todo:  # a walker redone for another height is incomplete until it is done
        (out / f"{n}.json").unlink(missing_ok=True)
    with dask_client(scheduler, jobs) as client:
        from distributed import as_completed  # the [dist] extra's

        t0 = time.perf_counter()
        workers = len(client.scheduler_info(n_workers=-1)["workers"])
        futures, jobs_of = [], {}
        if todo:
            # a key of its own (hash=False): scattered under its content's hash, a model run
            # again on the same cluster took the key the last run was releasing, and its
            # recordings failed with "lost data" (seen in test_batch's re-runs, 2 in ~20)
            shared = client.scatter(blob, broadcast=True, hash=False)
            job = uuid.uuid4().hex[:8]
            for n, r in todo:
                fut = client.submit(reconstruct_one, r, str(out), n, sha, shared,
                                    placement=placement, fmt=fmt, calibrate=calibrate,
                                    platform=platform, height_m=heights[n], unit=unit,
                                    skeleton=None if skeleton is None else str(skeleton),
                                    timeout_s=timeout_s, rig=rig, columns=columns,
                                    key=f"imuloco-batch-{job}-{n}", retries=retries,
                                    pure=False)
                futures.append(fut)
                jobs_of[fut.key] = (n, r)
        bar = tqdm(total=len(names), initial=skipped, desc="batch", unit="rec",
                   disable=not progress)
        for fut in as_completed(futures):
            n, r = jobs_of[fut.key]
            if fut.status == "finished":
                res = fut.result()
                rows[n], strides[n] = res["row"], stride_table(res["strides"])
                for w in res.get("warnings", ()):  # the worker's, once per kind on the console
                    log.warning("%s: %s", n, w["text"], extra={"kind": w["kind"]})
            else:  # lost more often than Dask allows, or raised more than ``retries`` times
                rows[n], strides[n] = error_row(n, r, fut.exception(), 0.0), stride_table([])
            fut.release()
            bar.set_postfix_str(f"{n}: {rows[n]['status']}")
            bar.update()
        bar.close()
    seconds = time.perf_counter() - t0
    ordered = [{k: rows[n].get(k) for k in WALKER_FIELDS}
               | {"height_m": heights[n], "method": fitted.name, "model": note}
               | study.columns(n) for n in names]
    all_strides = [strides[n] for n in names]
    write_tables(out, ordered, all_strides, inputs=inputs, extra=study.fields)
    failed = sum(r["status"] != "ok" for r in ordered)
    summary = {"model": note, "method": fitted.name, "model_sha256": sha, "jobs": workers,
               "scheduler": scheduler if isinstance(scheduler, str) else None,
               "model_seconds": round(model_seconds, 2), "seconds": round(seconds, 2),
               "done": len(names) - skipped - failed, "skipped": skipped,
               "ok": len(names) - failed, "failed": failed,
               "frames": sum(r["frames"] or 0 for r in ordered),
               "strides": sum(t.num_rows for t in all_strides),
               "recordings": [{k: r[k] for k in (*COLUMNS, *(x.name for x in study.fields))}
                              for r in ordered]}
    with atomic_write(check_output(out / "summary.json", force=True, inputs=inputs), "w") as f:
        f.write(json.dumps(summary, indent=2) + "\n")
    return summary
