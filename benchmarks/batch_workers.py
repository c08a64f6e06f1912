"""Is the heavy stack loaded once per ``batch`` worker process, not once per recording?

    python benchmarks/batch_workers.py [--walkers 8] [--seconds 30] [--workers 2]

Runs :func:`imuloco.app.batch.run_batch` on ``--walkers`` simulated walkers
(:func:`imuloco.lab.batchbench.make_crowd`, the shipped right-ankle model) on a local Dask
cluster of ``--workers`` single-threaded processes. Before the run each worker wraps
``load_model`` and the per-recording task with counters, through ``Client.run``; after it,
prints per worker: recordings, model loads, whether torch and the method stack were imported
before its first recording, and each recording's wall and CPU seconds (the first one pays the
imports and the model's loading, later ones should not).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

from distributed import Client, LocalCluster

from imuloco.app.batch import LOCAL_CLUSTER, run_batch
from imuloco.lab.batchbench import make_crowd

STACK = ("torch", "scipy", "sklearn", "imuloco.methods.learned", "imuloco.app.pipeline")


def install_counters() -> dict:
    """On a worker: count ``load_model`` calls and time each recording's task; returns which
    of :data:`STACK` the worker had imported before (and before these counters)."""
    before = {m: m in sys.modules for m in STACK}
    from imuloco.app import batch  # on the worker, after looking at what it had imported
    from imuloco.methods import modelfile

    stats = {"loads": 0, "load_s": 0.0, "tasks": [], "before_first": before}
    load, task = modelfile.load_model, batch._reconstruct_one

    def counted_load(*args, **kwargs):
        t0 = time.perf_counter()
        try:
            return load(*args, **kwargs)
        finally:
            stats["loads"] += 1
            stats["load_s"] += time.perf_counter() - t0

    def timed_task(*args, **kwargs):
        wall, cpu = time.perf_counter(), time.process_time()
        try:
            return task(*args, **kwargs)
        finally:
            stats["tasks"].append((time.perf_counter() - wall, time.process_time() - cpu))

    modelfile.load_model, batch._reconstruct_one = counted_load, timed_task
    batch._STARTUP_STATS = stats
    return stats["before_first"]


def collect() -> dict:
    from imuloco.app import batch

    return batch._STARTUP_STATS


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--walkers", type=int, default=8)
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="imuloco-workers-") as tmp:
        logs = make_crowd(args.walkers, Path(tmp) / "crowd", args.seconds)
        with LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True,
                          **LOCAL_CLUSTER) as cluster, Client(cluster) as client:
            client.run(install_counters)
            summary = run_batch(logs, Path(tmp) / "out", method="learned", scheduler=client,
                                timeout_s=None)
            per_worker = client.run(collect)
    print(f"{args.walkers} walkers of {args.seconds:g} s on {args.workers} workers: "
          f"{summary['done']} done, {summary['failed']} failed, {summary['seconds']:.1f} s")
    for address, s in sorted(per_worker.items()):
        tasks = s["tasks"]
        later = tasks[1:]
        print(json.dumps({
            "worker": address, "recordings": len(tasks), "model_loads": s["loads"],
            "model_load_s": round(s["load_s"], 2),
            "imported_before_first_recording": s["before_first"],
            "first_recording_s": [round(v, 2) for v in tasks[0]] if tasks else None,
            "later_recordings_median_s": ([round(statistics.median(t[i] for t in later), 2)
                                           for i in (0, 1)] if later else None)}))


if __name__ == "__main__":
    main()
