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
- Timings use one BLAS/OpenMP thread (threadpoolctl), like a single core.
- Methods are registry names, each optionally with hyperparameters (``mousas2017[beam=256]``,
  :func:`imuloco.methods.registry.parse_method_spec`). Specs of one method that differ only
  in hyperparameters its class lists in ``stream_params`` (they change the online stream, not
  the fit) share one fitted model per size; their streams are timed one after the other, in
  the same minutes, with the test clip's MPJPE (``mpjpe_cm``, streamed from its first frame).
- ``against=REV`` also times, for each fitted model, the stream class of git commit ``REV``
  (its module loaded from git, on today's fitted model): the old code in the same run,
  recorded as ``"<spec> @ REV"``.
- ``online_fps`` is steps over their total wall time; latencies are per step, in ms, wall
  clock. On a shared machine other processes inflate wall times, so each record also has
  ``online_fps_cpu`` and ``online_cpu_ms_p50`` from this thread's CPU time and the 1-minute
  ``load_avg`` when it was measured.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from imuloco.core.motion import MotionDatabase
from imuloco.evaluate.protocols import in_random_test
from imuloco.methods.training import TEST_SEED_OFFSET, Example, synthesize

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


def time_stream(make_stream: Callable[[], Any], signals: np.ndarray,
                min_steps: int = MIN_STEPS, warmup: int = WARMUP
                ) -> tuple[np.ndarray, np.ndarray]:
    """Per-step wall times and CPU times of this thread (s) of streaming ``signals`` (T, C)
    through a new ``make_stream()``, looped to ``min_steps``. The CPU time leaves out the time
    other processes hold the core, which on a shared machine is most of a wall-clock
    outlier."""
    stream = make_stream()
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


def stream_mpjpe(make_stream: Callable[[], Any], test: Example) -> float:
    """MPJPE (cm) of a new stream over the test clip's signals, from its first frame."""
    from imuloco.core.motion import Motion
    from imuloco.evaluate.metrics import mpjpe

    stream = make_stream()
    out = [stream.step(s) for s in test.signals]
    motion = Motion(test.motion.skeleton, np.stack([o[0] for o in out]),
                    np.stack([o[1] for o in out]), test.motion.fps)
    return mpjpe(test.motion, motion)


def old_stream_factory(rev: str, method) -> Callable[[], Any]:
    """A factory of the stream class of ``method`` as it was at git commit ``rev`` (its
    module loaded from git; the class built on today's fitted ``method``)."""
    from imuloco.evaluate.loadspeed import module_at

    cls = type(method.stream())
    relpath = "src/" + cls.__module__.replace(".", "/") + ".py"
    old = getattr(module_at(rev, relpath, f"{cls.__module__}_at_{rev}"), cls.__name__)
    return lambda: old(method)


def _fit(name: str, params: dict[str, Any], examples: list[Example], placements: list[str],
         noise: str):
    """A method fitted on already simulated examples (:meth:`Method.fit_set`), so that every
    size and method shares one simulation."""
    from imuloco.methods import get_method
    from imuloco.methods.training import TrainingSet

    return get_method(name, **params).fit_set(TrainingSet.from_examples(examples, placements,
                                                                        noise))


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
    methods : registry names of online methods, optionally with hyperparameters
        (``name[key=value;...]``; offline ones get a record with None timings).
    out : output folder.
    data : folder of clips (None: the bundled sample, repeated for the large sizes).
    db_frames : database sizes in frames (default :data:`DEFAULT_SIZES`).
    placements, noise, seed : sensors simulated for training and the test clip.
    params : hyperparameters per method spec (added to the spec's own).
    against : a git commit whose stream classes are timed too (see the module docstring).

    The largest database is simulated once; each size takes its first frames (clips in the
    fixed order of :func:`build_database`, the last one cut).

    Returns the records, by method spec then size: ``method``, ``db_frames``,
    ``online_fps``, ``online_latency_ms_p50``, ``online_latency_ms_p99``, plus
    ``requested_frames``, ``clips``, ``repeated``, ``distinct_frames``, ``fit_s``, ``steps``,
    ``online_fps_cpu``, ``online_cpu_ms_p50``, ``load_avg``, ``mpjpe_cm`` and ``states``
    (the method's state count when it has one).
    """
    from imuloco.evaluate.bench import load_data
    from imuloco.methods import method_class
    from imuloco.methods.registry import parse_method_spec

    specs = {m: parse_method_spec(m) for m in methods}
    for name, _ in specs.values():  # fail before any work on an unknown or uninstalled method
        method_class(name)
    sizes = list(db_frames or DEFAULT_SIZES)
    placements = list(placements)
    db, test_db = _split_test(load_data(data))
    test = synthesize(test_db, placements, noise, seed + TEST_SEED_OFFSET)[0]
    big, _ = build_database(db, max(sizes), seed)
    examples = synthesize(big, placements, noise, seed)
    records: dict[str, list[dict[str, Any]]] = {}
    with threadpool_limits(limits=1):
        for size in sizes:
            sub, info = _prefix(examples, size)
            fitted: dict[str, tuple[Any, dict[str, Any]]] = {}
            for spec, (name, spec_params) in specs.items():
                cls = method_class(name)
                p = {**spec_params, **(params or {}).get(spec, {})}
                online = {k: v for k, v in p.items() if k in cls.stream_params}
                key = json.dumps([name, {k: v for k, v in p.items() if k not in online}],
                                 sort_keys=True, default=str)
                first = key not in fitted
                if first:
                    t0 = time.perf_counter()
                    method = _fit(name, {k: v for k, v in p.items() if k not in online}, sub,
                                  placements, noise)
                    fitted[key] = method, {"fit_s": round(time.perf_counter() - t0, 2),
                                           "defaults": method.get_params()}
                method, facts = fitted[key]
                method.set_params(**({k: facts["defaults"][k] for k in cls.stream_params}
                                     | online))
                rec: dict[str, Any] = {"method": spec, "requested_frames": size, **info,
                                       "fit_s": facts["fit_s"]}
                lower = getattr(method, "lower_", None)
                rec["states"] = int(lower.num_states) if lower is not None else None
                runs = [(spec, method.stream)]
                if against and first and method.supports_online:
                    runs.append((f"{spec} @ {against}", old_stream_factory(against, method)))
                for label, make in runs:
                    r = dict(rec, method=label)
                    r.update(_timed(make, test) if method.supports_online else _offline())
                    records.setdefault(label, []).append(r)
            del fitted
    flat = [r for recs in records.values() for r in recs]
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "speed.json").write_text(json.dumps(flat, indent=1) + "\n")
    (out / "speed.md").write_text(speed_table(flat, data) + "\n")
    return flat


def _timed(make_stream: Callable[[], Any], test: Example) -> dict[str, Any]:
    """The timing fields of a record (see :func:`speed_benchmark`)."""
    load = os.getloadavg()[0]
    dt, cpu = time_stream(make_stream, test.signals)
    ms, cpu_ms = dt * 1e3, cpu * 1e3
    return {"online_fps": float(len(dt) / dt.sum()),
            "online_latency_ms_p50": float(np.percentile(ms, 50)),
            "online_latency_ms_p99": float(np.percentile(ms, 99)),
            "online_fps_cpu": float(len(cpu) / cpu.sum()),
            "online_cpu_ms_p50": float(np.percentile(cpu_ms, 50)),
            "steps": len(dt), "load_avg": round(load, 2), "cpu_count": os.cpu_count(),
            "mpjpe_cm": round(stream_mpjpe(make_stream, test), 4)}


def _offline() -> dict[str, Any]:
    return {"online_fps": None, "online_latency_ms_p50": None, "online_latency_ms_p99": None,
            "online_fps_cpu": None, "online_cpu_ms_p50": None, "steps": 0, "mpjpe_cm": None}


def speed_table(records: list[dict[str, Any]], data: Path | None = None) -> str:
    """A markdown table of speed records."""
    def f(v: Any, fmt: str) -> str:
        return "-" if v is None else format(v, fmt)

    source = "bundled sample" if data is None else Path(data).name
    lines = [f"# Online speed against database size ({source}, one thread)", "",
             ("| method | db frames | states | fps | latency p50 ms | latency p99 ms | fps (CPU) "
             "| CPU ms p50 | MPJPE cm (test clip) | load | fit s | repeated clips |"),
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    for r in records:
        lines.append(
            f"| {r['method']} | {r['db_frames']} | {f(r.get('states'), 'd')} "
            f"| {f(r['online_fps'], '.0f')} | {f(r['online_latency_ms_p50'], '.3f')} "
            f"| {f(r['online_latency_ms_p99'], '.3f')} | {f(r.get('online_fps_cpu'), '.0f')} "
            f"| {f(r.get('online_cpu_ms_p50'), '.3f')} | {f(r.get('mpjpe_cm'), '.2f')} "
            f"| {f(r.get('load_avg'), '.1f')} "
            f"| {f(r.get('fit_s'), '.1f')} "
            f"| {'yes (' + str(r['distinct_frames']) + ' distinct)' if r.get('repeated') else 'no'} |")
    return "\n".join(lines)
