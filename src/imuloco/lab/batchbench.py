"""Throughput benchmark of :func:`imuloco.app.batch.run_batch` (``imuloco bench --batch N``).

A crowd of ``N`` simulated walkers, each ``seconds`` long, is reconstructed with one model:

1. on a local cluster of 1 worker process, then of 2 (recordings per minute, speed-up, peak
   resident memory of every worker process);
2. on a cluster started the way a user starts one, by its own commands on 127.0.0.1: ``dask
   scheduler --host 127.0.0.1 --port P`` and two ``dask worker tcp://127.0.0.1:P`` processes;
   its ``walkers.parquet`` and ``strides.parquet`` are compared with the local 2-worker run's.

Protocol details fixed here:

- A walker is the bundled sample's walking clips (straight and turning, every style) chained
  in a seeded random order until ``seconds`` are filled: each next clip is turned about the
  vertical and moved so that it starts where and facing where the previous one ended (the pose
  still jumps at a seam, as between two takes). Its phone at ``placement`` is simulated with
  ``phone`` noise and the walker's seed, so the phone's mount on the leg (misalignment,
  offset), sampling jitter and sensor noise differ between walkers.
- ``recordings_per_min`` is walkers over the wall time from the first task submitted to the
  last result (the cluster's start-up and the tables are counted apart, ``startup_s``), so it
  is what a long run on that many workers sustains. The machine may be shared: the record
  keeps the 1-minute load average before and after each run, and ``os.cpu_count()``.
- ``worker_cpu_s_per_recording`` is the CPU time (user + system) the worker processes spent
  during the run over the walkers: what a recording costs a core of its own, whatever the load.
- Peak memory is each worker process's ``ru_maxrss`` (Linux: kB) at the end of the run.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from imuloco.app.batch import dask_client, run_batch
from imuloco.app.pipeline import choose_method
from imuloco.core.motion import Motion
from imuloco.io.atomic import atomic_write
from imuloco.io.database import load_sample
from imuloco.io.sensorlog import write_generic_csv
from imuloco.ops.heading import heading_from_hips
from imuloco.ops.rotations import about_y, qmul, qrot
from imuloco.sensors.simulate import simulate

WALKING = ("walk", "walk-turn-left", "walk-turn-right")
STARTUP_TIMEOUT_S = 60.0


def walker_motion(clips: list[Motion], seconds: float, seed: int) -> Motion:
    """Clips chained in a seeded random order into one motion of ``seconds`` (see the module
    docstring); all clips share one skeleton and frame rate."""
    rng = np.random.default_rng(seed)
    first = clips[0]
    need = round(seconds * first.fps)
    rots, roots, frames = [], [], 0
    end, heading = np.zeros(3), 0.0
    while frames < need:
        clip = clips[int(rng.integers(len(clips)))]
        hips = clip.part_positions(["left_hip", "right_hip"])
        start = float(heading_from_hips(hips[0, 0], hips[0, 1]))
        q = about_y(np.array(heading - start))
        root = qrot(q, clip.root - clip.root[0] * [1, 0, 1]) + end * [1, 0, 1]
        rot = clip.rotations.copy()
        rot[:, 0] = qmul(q, rot[:, 0])
        rots.append(rot)
        roots.append(root)
        frames += clip.num_frames
        # where the next clip starts: this one's last frame, one frame's step further
        end = 2 * root[-1] - root[-2]
        last = hips[-1]
        heading = float(heading_from_hips(qrot(q, last[0]), qrot(q, last[1])))
    return Motion(first.skeleton, np.concatenate(rots)[:need], np.concatenate(roots)[:need],
                  first.fps, f"walker_seed{seed}")


def make_crowd(n: int, out_dir: str | Path, seconds: float = 60.0,
               placement: str = "right_ankle", seed: int = 0) -> list[Path]:
    """Write ``n`` simulated walkers' phone logs (generic CSV) into ``out_dir``."""
    db = load_sample()
    clips = [c for c, lab in zip(db.clips, db.labels) if lab.get("content") in WALKING]
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for k in range(n):
        path = out / f"walker{k:05d}.csv"
        if not path.exists():  # the crowd is a fixed function of (n, seconds, seed)
            rec = simulate(walker_motion(clips, seconds, seed + k), [placement], 100.0,
                           "phone", seed=seed + k)
            write_generic_csv(rec, path)
        paths.append(path)
    return paths


def _peak_rss_kb() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss


def _cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def _load() -> float:
    return round(os.getloadavg()[0], 2)


def _run(logs: list[Path], out: Path, fitted, scheduler=None, jobs: int = 1
         ) -> dict[str, Any]:
    """One batch run on a cluster of ``jobs`` workers (started here unless ``scheduler``),
    with its figures."""
    if out.exists():
        shutil.rmtree(out)  # the benchmark's own scratch output
    load_before = _load()
    t0 = time.perf_counter()
    with dask_client(scheduler, jobs) as client:
        client.wait_for_workers(jobs, timeout=STARTUP_TIMEOUT_S)
        startup = time.perf_counter() - t0
        cpu0 = client.run(_cpu_s)
        summary = run_batch(logs, out, fitted=fitted, scheduler=client)
        cpu = sum(v - cpu0[k] for k, v in client.run(_cpu_s).items())
        peak = client.run(_peak_rss_kb)
    n = len(logs)
    return {"workers": summary["jobs"], "recordings": n, "ok": summary["ok"],
            "failed": summary["failed"], "seconds": summary["seconds"],
            "recordings_per_min": round(n / summary["seconds"] * 60, 2),
            "worker_cpu_s_per_recording": round(cpu / n, 2),
            "startup_s": round(startup, 2),
            "peak_rss_mb_per_worker": sorted(round(v / 1024, 1) for v in peak.values()),
            "load_avg_1min": [load_before, _load()]}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _same_tables(a: Path, b: Path) -> dict[str, Any]:
    """Whether two batch outputs hold the same tables (the timing column aside)."""
    import pyarrow.parquet as pq  # the [dist] extra's (batch writes parquet with it)

    result = {}
    for name, drop in (("walkers.parquet", ["seconds"]), ("strides.parquet", [])):
        ta, tb = (pq.read_table(d / name).drop_columns(drop) for d in (a, b))
        result[name] = {"rows": ta.num_rows, "equal": ta.equals(tb)}
    return result


def _external_cluster(logs: list[Path], out: Path, fitted, workers: int = 2
                      ) -> dict[str, Any]:
    """The job on ``dask scheduler`` + ``workers`` ``dask worker`` processes on 127.0.0.1,
    each started by its own command and stopped afterwards."""
    dask = str(Path(sys.executable).with_name("dask"))
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    commands = [[dask, "scheduler", "--host", "127.0.0.1", "--port", str(port),
                 "--no-dashboard"]]
    commands += [[dask, "worker", address, "--nthreads", "1", "--nworkers", "1",
                  "--no-dashboard", "--name", f"bench-{k}"] for k in range(workers)]
    procs = []
    try:
        for cmd in commands:
            procs.append(subprocess.Popen(cmd, stdout=subprocess.DEVNULL,
                                          stderr=subprocess.DEVNULL))
            if cmd[1] == "scheduler":
                _wait_for_port(port)
        record = _run(logs, out, fitted, scheduler=address, jobs=workers)
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in reversed(procs):
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
    record["commands"] = [" ".join(["dask", *c[1:]]) for c in commands]
    return record


def _wait_for_port(port: int) -> None:
    deadline = time.monotonic() + STARTUP_TIMEOUT_S
    while time.monotonic() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.2)
    raise TimeoutError(f"dask scheduler did not listen on 127.0.0.1:{port} within "
                       f"{STARTUP_TIMEOUT_S:.0f} s")


def batch_benchmark(n: int, out_dir: str | Path, seconds: float = 60.0, method: str | None = None,
                    placement: str = "right_ankle", workers: tuple[int, ...] = (1, 2),
                    external: bool = True) -> dict[str, Any]:
    """Run the benchmark (see the module docstring); write ``batch_bench.json`` and
    ``batch_bench.md`` into ``out_dir`` and return the record."""
    out = Path(out_dir)
    logs = make_crowd(n, out / "crowd", seconds, placement)
    fitted, note = choose_method(method, None, placement)
    record: dict[str, Any] = {"walkers": n, "seconds_each": seconds, "placement": placement,
                              "method": fitted.name, "model": note, "cpu_count": os.cpu_count(),
                              "local": []}
    for w in workers:
        record["local"].append(_run(logs, out / f"local-{w}", fitted, jobs=w))
    base = record["local"][0]["recordings_per_min"]
    for r in record["local"]:
        r["speedup"] = round(r["recordings_per_min"] / base, 2)
    if external:
        ref = out / f"local-{workers[-1]}"
        record["scheduler"] = _external_cluster(logs, out / "scheduler", fitted)
        record["scheduler"]["same_tables_as_local"] = _same_tables(ref, out / "scheduler")
    with atomic_write(out / "batch_bench.json", "w") as f:
        f.write(json.dumps(record, indent=2) + "\n")
    with atomic_write(out / "batch_bench.md", "w") as f:
        f.write(markdown(record))
    return record


def markdown(record: dict[str, Any]) -> str:
    """The benchmark's table."""
    head = (f"{record['walkers']} walkers of {record['seconds_each']:.0f} s, "
            f"{record['method']} at {record['placement']}, {record['cpu_count']} CPUs")
    columns = ("| cluster | workers | recordings/min | speed-up | worker CPU s per recording "
               "| peak MB per worker | start-up s | load avg before/after |")
    lines = [head, "", columns, "|---|---:|---:|---:|---:|---|---:|---|"]
    runs = [("local", r) for r in record["local"]]
    if "scheduler" in record:
        runs.append(("dask scheduler + dask worker", record["scheduler"]))
    for kind, r in runs:
        lines.append(f"| {kind} | {r['workers']} | {r['recordings_per_min']:.2f} | "
                     f"{r.get('speedup', '–')} | {r['worker_cpu_s_per_recording']:.1f} | "
                     f"{', '.join(f'{v:.0f}' for v in r['peak_rss_mb_per_worker'])} | "
                     f"{r['startup_s']:.1f} | {' / '.join(map(str, r['load_avg_1min']))} |")
    if "scheduler" in record:
        same = record["scheduler"]["same_tables_as_local"]
        lines += ["", "Tables of the scheduler run against the local run: " + ", ".join(
            f"{k} {v['rows']} rows {'identical' if v['equal'] else 'DIFFERENT'}"
            for k, v in same.items())]
    return "\n".join(lines) + "\n"
