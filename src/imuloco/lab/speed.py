"""Speed benchmark of online methods over database sizes (``imuloco bench --speed``).

For each size, a database of that many frames is built from the data (clips taken in a fixed
shuffled order; the last one cut to size), the method is fitted on it, and one held-out test
clip is streamed frame by frame through :meth:`Method.stream` with each ``step`` timed.
Mousas 2017 (Table 2) reports 65 fps at 500 frames falling to 12 fps at 10,000.

Protocol details fixed here:

- The largest database is simulated once and every size takes its first frames, so sizes
  and methods share one simulation (and the sensor noise of a clip is the same in all).
- The test clip is the first clip of the ``random-clips`` test split and is never in the
  database; its signals are simulated with the test seed offset. It is streamed for at least
  :data:`MIN_STEPS` steps (looped when shorter), after :data:`WARMUP` untimed steps.
- When the data hold fewer frames than a size asks for, clips are repeated; each copy is
  renamed (``name~rep2``...) so that its simulated sensor noise differs, and the record says
  ``repeated: true`` with the number of distinct frames.
- Every fitted method also reconstructs the test clip offline (:meth:`Method.reconstruct_signals`
  of its signals looped to :data:`MIN_STEPS` frames, after an untimed one of :data:`WARMUP`
  frames; wall and CPU: ``offline_fps``, ``offline_fps_cpu``) and the record has the MPJPE of
  the clip's own reconstruction (``test_mpjpe_cm``, heading-aligned at the first frame as in
  :mod:`imuloco.lab.bench`): the same clip for every method, size and revision.
- ``against``: each method is also fitted and timed as its module was at that git commit
  (the module file from git, on today's package; for a method that is a package of modules,
  such as ``mousas2017``, the names its module takes from that package at that commit too;
  record ``method`` ``NAME@REV``), right after today's, on the same database and test clip: a
  speed-up against the old code in one run.
- Methods are registry names, each optionally with hyperparameters (``mousas2017[beam=256]``,
  :func:`imuloco.methods.registry.parse_method_spec`). Specs of one method that differ only in
  hyperparameters its class lists in ``stream_params`` (they change the online stream, not the
  fit) share one fitted model per size and are timed one after the other.
- Timings use one BLAS/OpenMP thread (threadpoolctl), like a single core.
- ``online_fps`` is steps over their total wall time; latencies are per step, in ms, wall
  clock. On a shared machine other processes inflate wall times, so each record also has
  ``online_fps_cpu`` and ``online_cpu_ms_p50`` from this thread's CPU time and the 1-minute
  ``load_avg`` when it was measured.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from threadpoolctl import threadpool_limits

from imuloco.core.motion import MotionDatabase
from imuloco.errors import InputError
from imuloco.io.atomic import atomic_write
from imuloco.lab.bench import load_data
from imuloco.lab.loadspeed import module_at
from imuloco.lab.protocols import in_random_test
from imuloco.measures import metrics
from imuloco.methods import method_class
from imuloco.methods.registry import parse_method_spec
from imuloco.methods.training import TEST_SEED_OFFSET, Example, TrainingSet, synthesize

DEFAULT_SIZES = (500, 1000, 2000, 5000, 10000, 20000, 50000, 100000)
MIN_STEPS = 300
WARMUP = 10
MIN_CLIP = 60  # frames: a clip cut shorter than this is left out (too short to segment)


def build_database(db: MotionDatabase, frames: int, seed: int = 0
                   ) -> tuple[MotionDatabase, dict[str, Any]]:
    """A database of about ``frames`` frames from ``db`` (see the module docstring).

    Returns the database and facts about it: ``db_frames`` (actual), ``clips``, ``repeated``,
    ``distinct_frames``.
    """
    if len(db) == 0:
        raise ValueError("build_database: empty database")
    order = np.random.default_rng(seed).permutation(len(db))
    clips, labels, total, k = [], [], 0, 0
    used: dict[int, int] = {}
    while total < frames:
        i = int(order[k % len(db)])
        rep = k // len(db)
        k += 1
        motion, lab = db.clips[i], dict(db.labels[i])
        need = frames - total
        if motion.num_frames > need:
            if need < MIN_CLIP:
                if clips:
                    break
                need = min(motion.num_frames, MIN_CLIP)
            motion = motion.slice(0, need)
        if rep:
            lab["name"] = f"{lab['name']}~rep{rep + 1}"
        clips.append(motion)
        labels.append(lab)
        used[i] = max(used.get(i, 0), motion.num_frames)
        total += motion.num_frames
    info = {"db_frames": int(total), "clips": len(clips), "repeated": k > len(db),
            "distinct_frames": int(sum(used.values()))}
    return MotionDatabase(clips, labels), info


def _split_test(db: MotionDatabase) -> tuple[MotionDatabase, MotionDatabase]:
    test = [i for i, lab in enumerate(db.labels) if in_random_test(lab["name"])]
    if not test:
        test = [len(db) - 1]
    rest = [i for i in range(len(db)) if i != test[0]]
    return db.subset(rest), db.subset(test[:1])


def time_stream(method, signals: np.ndarray, min_steps: int = MIN_STEPS,
                warmup: int = WARMUP) -> tuple[np.ndarray, np.ndarray]:
    """Per-step wall times and CPU times of this thread (s) of streaming ``signals`` (T, C),
    looped to ``min_steps``. The CPU time leaves out the time other processes hold the core,
    which on a shared machine is most of a wall-clock outlier."""
    stream = method.stream()
    for sample in signals[:warmup]:
        stream.step(sample)
    reps = int(np.ceil(min_steps / len(signals)))
    rows = np.concatenate([signals] * reps)[:max(min_steps, len(signals))]
    out = np.empty(len(rows))
    cpu = np.empty(len(rows))
    clock, cpu_clock = time.perf_counter, time.thread_time
    for t, sample in enumerate(rows):
        t0, c0 = clock(), cpu_clock()
        stream.step(sample)
        out[t], cpu[t] = clock() - t0, cpu_clock() - c0
    return out, cpu


def _prefix(examples: list[Example], frames: int) -> tuple[list[Example], dict[str, Any]]:
    """The first ``frames`` frames of a list of examples (the last one cut), as
    :func:`build_database` would pick them."""
    out, total = [], 0
    for ex in examples:
        need = frames - total
        if need <= 0:
            break
        n = ex.motion.num_frames
        if n > need:
            if need < MIN_CLIP and out:
                break
            n = max(min(n, MIN_CLIP), need)
            ex = Example(ex.motion.slice(0, n), ex.signals[:n], ex.labels)
        out.append(ex)
        total += n
    names: dict[str, int] = {}
    for e in out:
        key = e.labels["name"].split("~rep")[0]
        names[key] = max(names.get(key, 0), e.motion.num_frames)
    info = {"db_frames": int(total), "clips": len(out),
            "repeated": any("~rep" in e.labels["name"] for e in out),
            "distinct_frames": int(sum(names.values()))}
    return out, info


def _module_at(rev: str, module: str):
    return module_at(rev, "src/" + module.replace(".", "/") + ".py",
                     f"imuloco_at_{rev}_{module.replace('.', '_')}")


def method_at(name: str, rev: str) -> type:
    """The class of method ``name`` as it was at git commit ``rev``: its module's file at that
    commit run on today's package (a source checkout is needed), named ``NAME@REV``. When the
    method is a package (``imuloco.methods.mousas2017``), what its module takes from the
    package's other modules (stream, forward step, model) is taken from them at ``rev``."""
    cls = method_class(name)
    module = _module_at(rev, cls.__module__)
    package = cls.__module__.rpartition(".")[0]
    if package != "imuloco.methods":
        siblings: dict[str, Any] = {}
        for key, obj in list(vars(module).items()):
            src = getattr(obj, "__module__", None)
            if isinstance(src, str) and src.startswith(package + ".") \
                    and src != cls.__module__:
                if src not in siblings:
                    siblings[src] = _module_at(rev, src)
                if hasattr(siblings[src], key):
                    setattr(module, key, getattr(siblings[src], key))
    old = getattr(module, cls.__qualname__)
    old.name = f"{name}@{rev}"  # the entry point names today's class only
    return old


def _fit(cls: type, params: dict[str, Any], examples: list[Example], placements: list[str],
         noise: str):
    """A method of class ``cls`` fitted on already simulated examples
    (:meth:`Method.fit_set`), so that every size and method shares one simulation."""
    return cls(**params).fit_set(TrainingSet.from_examples(examples, placements, noise))


def time_offline(method, test: Example, min_frames: int = MIN_STEPS, warmup: int = WARMUP
                 ) -> dict[str, Any]:
    """``offline_fps`` (wall) and ``offline_fps_cpu`` (this thread's CPU time) of one
    :meth:`reconstruct_signals` of the test example's signals, looped to ``min_frames``,
    after an untimed one of its first ``warmup`` frames (which builds what a method builds on
    first use); and ``test_mpjpe_cm``, the MPJPE of the test example's reconstruction."""
    method.reconstruct_signals(test.signals[:warmup])
    rows = np.concatenate([test.signals] * int(np.ceil(min_frames / len(test.signals))))
    t0, c0 = time.perf_counter(), time.thread_time()
    method.reconstruct_signals(rows)
    wall, cpu = time.perf_counter() - t0, time.thread_time() - c0
    motion = metrics.align_heading(method.reconstruct_signals(test.signals), test.motion, 0)
    return {"offline_fps": len(rows) / wall if wall > 0 else None,
            "offline_fps_cpu": len(rows) / cpu if cpu > 0 else None,
            "offline_frames": len(rows),
            "test_mpjpe_cm": float(metrics.evaluate(test.motion, motion)["mpjpe_cm"])}


class _Run(NamedTuple):
    """One timed variant: its method spec, its record's label, the class, the fit's
    hyperparameters and the stream's (``stream_params``)."""

    spec: str
    label: str
    cls: type
    fit_p: dict[str, Any]
    online: dict[str, Any]

    def fit_key(self) -> str:
        """Runs with the same key share one fitted model: same class, same fit
        hyperparameters."""
        return json.dumps([f"{self.cls.__module__}.{self.cls.__qualname__}", self.fit_p],
                          sort_keys=True, default=str)


def speed_benchmark(
    methods: Sequence[str],
    out: Path,
    data: Path | None = None,
    db_frames: Sequence[int] | None = None,
    placements: Sequence[str] = ("right_ankle",),
    noise: str = "phone",
    seed: int = 0,
    params: dict[str, dict[str, Any]] | None = None,
    against: str | None = None,
) -> list[dict[str, Any]]:
    """Time online reconstruction against database size; writes ``speed.json``/``speed.md``.

    Parameters
    ----------
    methods : registry names of methods, optionally with hyperparameters
        (``name[key=value;...]``; offline ones get a record with None online timings).
    out : output folder.
    data : folder of clips (None: the bundled sample, repeated for the large sizes).
    db_frames : database sizes in frames (default :data:`DEFAULT_SIZES`).
    placements, noise, seed : sensors simulated for training and the test clip.
    params : hyperparameters per method spec (added to the spec's own).
    against : a git commit: also time each method's code at that commit (``NAME@REV``).

    The largest database is simulated once; each size takes its first frames (clips in the
    fixed order of :func:`build_database`, the last one cut).

    Returns the records: ``method``, ``db_frames``, ``online_fps``, ``online_latency_ms_p50``,
    ``online_latency_ms_p99``, plus ``requested_frames``, ``clips``, ``repeated``,
    ``distinct_frames``, ``fit_s``, ``steps``, ``online_fps_cpu``, ``online_cpu_ms_p50``,
    ``load_avg``, ``states`` (the method's state count when it has one), ``offline_fps``,
    ``offline_fps_cpu`` and ``test_mpjpe_cm``.
    """
    # fail before any work on an unknown or uninstalled method or commit
    runs: list[_Run] = []
    for spec in methods:
        name, p = parse_method_spec(spec)
        cls = method_class(name)
        p = {**p, **(params or {}).get(spec, {})}
        online = {k: v for k, v in p.items() if k in cls.stream_params}
        fit_p = {k: v for k, v in p.items() if k not in online}
        runs.append(_Run(spec, spec, cls, fit_p, online))
        old_spec = spec if not online else name + (
            f"[{';'.join(f'{k}={v}' for k, v in fit_p.items())}]" if fit_p else "")
        if against and not any(r.label == f"{old_spec}@{against}" for r in runs):
            # the old code once per fitted model, without the stream hyperparameters (it
            # may not have them)
            runs.append(_Run(spec, f"{old_spec}@{against}", method_at(name, against), fit_p, {}))
    sizes = list(db_frames or DEFAULT_SIZES)
    placements = list(placements)
    db, test_db = _split_test(load_data(data))
    test = synthesize(test_db, placements, noise, seed + TEST_SEED_OFFSET)[0]
    big, _ = build_database(db, max(sizes), seed)
    examples = synthesize(big, placements, noise, seed)
    records = []
    with threadpool_limits(limits=1):
        fitted: dict[str, tuple[Any, float, dict[str, Any]]] = {}
        order = sorted(range(len(runs)), key=lambda i: runs[i].fit_key())  # shared fits adjacent
        for size in sizes:
            sub, info = _prefix(examples, size)
            for i in order:
                spec, label, cls, fit_p, online = runs[i]
                key = runs[i].fit_key()
                if key not in fitted:
                    fitted.clear()  # one fitted model held at a time
                    t0 = time.perf_counter()
                    method = _fit(cls, fit_p, sub, placements, noise)
                    fitted[key] = method, round(time.perf_counter() - t0, 2), \
                        method.get_params()
                method, fit_s, defaults = fitted[key]
                method.set_params(**({k: defaults[k] for k in cls.stream_params} | online))
                rec: dict[str, Any] = {"method": label, "requested_frames": size, **info,
                                       "fit_s": fit_s}
                lower = getattr(method, "lower_", None)
                rec["states"] = int(lower.num_states) if lower is not None else None
                if method.can_stream():
                    load = os.getloadavg()[0]
                    dt, cpu = time_stream(method, test.signals)
                    ms, cpu_ms = dt * 1e3, cpu * 1e3
                    rec.update(online_fps=float(len(dt) / dt.sum()),
                               online_latency_ms_p50=float(np.percentile(ms, 50)),
                               online_latency_ms_p99=float(np.percentile(ms, 99)),
                               online_fps_cpu=float(len(cpu) / cpu.sum()),
                               online_cpu_ms_p50=float(np.percentile(cpu_ms, 50)),
                               steps=len(dt), load_avg=round(load, 2),
                               cpu_count=os.cpu_count())
                else:
                    rec.update(online_fps=None, online_latency_ms_p50=None,
                               online_latency_ms_p99=None, online_fps_cpu=None,
                               online_cpu_ms_p50=None, steps=0,
                               load_avg=round(os.getloadavg()[0], 2))
                rec.update(time_offline(method, test))
                records.append((i, size, rec))
            fitted.clear()
    records = [r for _, _, r in sorted(records, key=lambda t: (t[0], sizes.index(t[1])))]
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    with atomic_write(out / "speed.json", "w") as f:
        f.write(json.dumps(records, indent=1) + "\n")
    with atomic_write(out / "speed.md", "w") as f:
        f.write(speed_table(records, data) + "\n")
    return records


def speed_table(records: list[dict[str, Any]], data: Path | None = None) -> str:
    """A markdown table of speed records."""
    def f(v: Any, fmt: str) -> str:
        return "-" if v is None else format(v, fmt)

    source = "bundled sample" if data is None else Path(data).name
    lines = [f"# Speed against database size ({source}, one thread)", "",
             ("| method | db frames | states | fps | latency p50 ms | latency p99 ms | fps (CPU) "
             "| CPU ms p50 | offline fps | offline fps (CPU) | test MPJPE cm | load | fit s "
             "| repeated clips |"),
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    for r in records:
        lines.append(
            f"| {r['method']} | {r['db_frames']} | {f(r.get('states'), 'd')} "
            f"| {f(r['online_fps'], '.0f')} | {f(r['online_latency_ms_p50'], '.3f')} "
            f"| {f(r['online_latency_ms_p99'], '.3f')} | {f(r.get('online_fps_cpu'), '.0f')} "
            f"| {f(r.get('online_cpu_ms_p50'), '.3f')} | {f(r.get('offline_fps'), '.1f')} "
            f"| {f(r.get('offline_fps_cpu'), '.1f')} | {f(r.get('test_mpjpe_cm'), '.4f')} "
            f"| {f(r.get('load_avg'), '.1f')} "
            f"| {f(r.get('fit_s'), '.1f')} "
            f"| {'yes (' + str(r['distinct_frames']) + ' distinct)' if r.get('repeated') else 'no'} |")
    return "\n".join(lines)


# ---- the reconstruct row: `imuloco reconstruct --report` timed as a user runs it ----------

RECONSTRUCT_LENGTHS = (60.0, 600.0, 3600.0)  # seconds: 1 min, 10 min, 1 h
SHIPPED_PLACEMENTS = ("right_ankle", "right_foot", "lower_back")  # one shipped model each
THREADS = ("1", "default")


def walk_log(placement: str, seconds: float, path: str | Path, seed: int = 0) -> Path:
    """A phone log of a ``seconds`` long walk of the sensor at ``placement`` (generic CSV,
    100 Hz): the bundled sample's walk clips simulated with phone noise and played end to
    end, repeated until long enough (each repetition's times continue the last)."""
    from imuloco.core.recording import Recording
    from imuloco.io.database import load_sample
    from imuloco.io.sensorlog import write_generic_csv
    from imuloco.sensors.simulate import simulate

    recs = [simulate(c, [placement], 100.0, "phone", seed + i)
            for i, c in enumerate(load_sample().where(content="walk").clips)]
    times, acc, gyro, t0, k = [], [], [], 0.0, 0
    while t0 < seconds:
        r = recs[k % len(recs)]
        keep = r.times - r.times[0] <= seconds - t0
        times.append(r.times[keep] - r.times[0] + t0)
        acc.append(r.acc[keep])
        gyro.append(r.gyro[keep])
        t0 = times[-1][-1] + 0.01
        k += 1
    rec = Recording(np.concatenate(times), np.concatenate(acc), np.concatenate(gyro),
                    [placement])
    return write_generic_csv(rec, path, overwrite=True)


def run_reconstruct(log: Path, placement: str, out: Path, src: Path, threads: str
                    ) -> dict[str, Any]:
    """``imuloco reconstruct LOG --placement P -o OUT --report OUT.json`` in a subprocess on
    the package in ``src`` (its PYTHONPATH): wall and CPU seconds (user + system, the
    child's own rusage) and its peak resident memory (MB). ``threads`` ``"1"``: one
    OpenMP/MKL thread (torch's and BLAS's), else their defaults."""
    env = {**os.environ, "PYTHONPATH": str(src)}
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        env.pop(var, None)
        if threads == "1":
            env[var] = "1"
    cmd = [sys.executable, "-c", "from imuloco.cli import main; main()", "reconstruct",
           str(log), "--placement", placement, "-o", str(out), "--report",
           str(out.with_suffix(".json")), "--force"]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True)
    err = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise RuntimeError(f"imuloco reconstruct failed on {log} ({src}):\n{err[-2000:]}")
    return {"wall_s": round(wall, 2), "cpu_s": round(usage.ru_utime + usage.ru_stime, 2),
            "peak_rss_mb": round(usage.ru_maxrss / 1024, 1)}  # ru_maxrss: kB on Linux


def bvh_difference(a: Path, b: Path) -> float:
    """Largest absolute difference of two BVHs' world joint positions (cm)."""
    from imuloco.io.bvh import read_bvh

    pa, pb = read_bvh(a).positions(), read_bvh(b).positions()
    if pa.shape != pb.shape:
        return float("inf")
    return float(np.abs(pa - pb).max() * 100.0)


def checkout(rev: str, folder: Path) -> Path:
    """The repository at git commit ``rev`` as a worktree in ``folder`` (``git worktree
    add --detach``); returns its ``src`` folder. :func:`remove_checkout` removes it."""
    root = Path(__file__).resolve().parents[3]
    try:
        subprocess.run(["git", "-C", str(root), "worktree", "add", "--detach", str(folder),
                        rev], check=True, capture_output=True, text=True)
    except (OSError, subprocess.CalledProcessError) as e:
        why = getattr(e, "stderr", None) or str(e)
        raise InputError(f"--against {rev}: cannot check it out from {root} ({why.strip()})"
                         ) from None
    return folder / "src"


def remove_checkout(folder: Path) -> None:
    root = Path(__file__).resolve().parents[3]
    subprocess.run(["git", "-C", str(root), "worktree", "remove", "--force", str(folder)],
                   check=False, capture_output=True)


def reconstruct_speed(lengths_s: Sequence[float] = RECONSTRUCT_LENGTHS,
                      placements: Sequence[str] = SHIPPED_PLACEMENTS,
                      threads: Sequence[str] = THREADS, against: str | None = None,
                      out: str | Path | None = None, progress: bool = False
                      ) -> list[dict[str, Any]]:
    """``imuloco reconstruct ... --report`` timed per placement, length and thread setting
    (see :func:`run_reconstruct`), on simulated walks (:func:`walk_log`) with the placement's
    shipped model. ``against``: the same runs on the code of that git commit (a temporary
    worktree, its own PYTHONPATH) right after today's, and ``max_diff_cm``, the largest
    difference of its BVH's joint positions from today's. Each record: ``placement``,
    ``length_s``, ``threads``, ``code`` (``today`` or the commit), ``wall_s``, ``cpu_s``,
    ``realtime`` (length over wall), ``realtime_cpu`` (length over CPU), ``peak_rss_mb``,
    ``load_avg`` (1 min, before the run). Written to ``out/reconstruct_speed.json`` and
    ``.md`` when ``out`` is given."""
    import tempfile

    from tqdm.auto import tqdm

    src = Path(__file__).resolve().parents[2]
    records: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="imuloco-speed-") as tmp:
        tmp = Path(tmp)
        codes = [("today", src)]
        if against is not None:
            codes.append((against, checkout(against, tmp / "old")))
        try:
            runs = [(p, s, t) for s in lengths_s for p in placements for t in threads]
            for placement, seconds, thread in tqdm(runs, desc="reconstruct speed",
                                                   disable=not progress):
                log = walk_log(placement, seconds, tmp / f"{placement}-{seconds:g}.csv")
                bvhs = []
                for code, path in codes:
                    bvh = tmp / f"{placement}-{seconds:g}-{thread}-{len(bvhs)}.bvh"
                    load = os.getloadavg()[0]
                    r = run_reconstruct(log, placement, bvh, path, thread)
                    r.update(placement=placement, length_s=seconds, threads=thread, code=code,
                             realtime=round(seconds / r["wall_s"], 1),
                             realtime_cpu=round(seconds / r["cpu_s"], 1),
                             load_avg=round(load, 1))
                    if bvhs:
                        r["max_diff_cm"] = bvh_difference(bvhs[0], bvh)
                    bvhs.append(bvh)
                    records.append(r)
                    if out is not None:  # after every run: a stopped bench keeps its rows
                        _write_reconstruct(records, Path(out))
                log.unlink()
        finally:
            if against is not None:
                remove_checkout(tmp / "old")
    return records


def _write_reconstruct(records: list[dict[str, Any]], out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    with atomic_write(out / "reconstruct_speed.json", "w") as f:
        f.write(json.dumps(records, indent=1) + "\n")
    with atomic_write(out / "reconstruct_speed.md", "w") as f:
        f.write(reconstruct_table(records) + "\n")


def reconstruct_table(records: list[dict[str, Any]]) -> str:
    """A markdown table of :func:`reconstruct_speed`'s records."""
    lines = [("| placement | length s | threads | code | wall s | CPU s | x real time (wall) "
              "| x real time (CPU) | peak RSS MB | max diff cm | load |"),
             "|---|---:|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in records:
        diff = r.get("max_diff_cm")
        lines.append(f"| {r['placement']} | {r['length_s']:g} | {r['threads']} | {r['code']} "
                     f"| {r['wall_s']:.1f} | {r['cpu_s']:.1f} | {r['realtime']:.0f} "
                     f"| {r['realtime_cpu']:.0f} | {r['peak_rss_mb']:.0f} "
                     f"| {'-' if diff is None else format(diff, '.2g')} | {r['load_avg']:.1f} |")
    return "\n".join(lines)
