"""Peak memory and time of `imuloco reconstruct` on a long simulated phone log.

    python benchmarks/long_recording.py HOURS [--one-piece] [--method NAME] [--keep DIR]

Writes a generic CSV log of HOURS hours at 100 Hz (a phone on the right ankle: one bundled walk
simulated with phone noise, repeated end to end with continuing timestamps, written block by
block), then runs ``imuloco reconstruct LOG -o OUT.bvh --piece-seconds 600`` (or in one piece
with ``--one-piece``) in a child process and prints its peak resident memory (the child's
``ru_maxrss``) and wall time. The log and BVH are deleted unless ``--keep DIR``.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def write_long_log(path: Path, hours: float, seed: int = 3) -> int:
    """A generic CSV of ``hours`` hours at 100 Hz; returns its rows."""
    from imuloco.io.database import load_sample
    from imuloco.sensors.simulate import simulate

    clip = load_sample().where(content="walk").clips[0]
    rec = simulate(clip, ["right_ankle"], 100.0, "phone", seed)
    block = np.concatenate([rec.times[:, None] - rec.times[0], rec.channels()], axis=1)
    span = block[-1, 0] + 0.01
    rows = int(hours * 3600 * 100)
    written = 0
    with open(path, "w") as f:
        f.write("time_s,acc_x,acc_y,acc_z,gyro_x,gyro_y,gyro_z\n")
        k = 0
        while written < rows:
            part = block[: rows - written].copy()
            part[:, 0] += k * span
            np.savetxt(f, part, delimiter=",", fmt=["%.6f"] + ["%.6g"] * 6)
            written += len(part)
            k += 1
    return written


def measure(cmd: list[str]) -> tuple[float, float]:
    """Peak RSS (MB) and seconds of ``cmd`` run in a fresh child process."""
    probe = ("import resource, subprocess, sys, time; t = time.perf_counter(); "
             "r = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL); "
             "s = time.perf_counter() - t; "
             "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, s, r.returncode)")
    run = subprocess.run([sys.executable, "-c", probe, *cmd], capture_output=True, text=True,
                         check=True)
    out = run.stdout.split()
    if out[2] != "0":
        raise SystemExit(f"{' '.join(cmd)} failed (exit {out[2]}): {run.stderr[-2000:]}")
    return int(out[0]) / 1024, float(out[1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("hours", type=float)
    ap.add_argument("--one-piece", action="store_true")
    ap.add_argument("--method", default=None, help="imuloco reconstruct --method")
    ap.add_argument("--piece-seconds", type=float, default=600.0)
    ap.add_argument("--keep", type=Path, default=None)
    args = ap.parse_args()
    folder = args.keep or Path(tempfile.mkdtemp(prefix="imuloco-long-"))
    folder.mkdir(parents=True, exist_ok=True)
    log, bvh = folder / f"long_{args.hours:g}h.csv", folder / f"long_{args.hours:g}h.bvh"
    t0 = time.perf_counter()
    rows = write_long_log(log, args.hours)
    made = time.perf_counter() - t0
    cmd = ["imuloco", "reconstruct", str(log), "-o", str(bvh), "--force"]
    cmd += [] if args.one_piece else ["--piece-seconds", str(args.piece_seconds)]
    cmd += [] if args.method is None else ["--method", args.method]
    rss, seconds = measure(cmd)
    result = {"hours": args.hours, "rows": rows, "log_mb": round(log.stat().st_size / 2**20),
              "bvh_mb": round(bvh.stat().st_size / 2**20), "one_piece": args.one_piece,
              "method": args.method or "default", "peak_rss_mb": round(rss),
              "seconds": round(seconds, 1), "log_written_s": round(made, 1)}
    print(json.dumps(result))
    if args.keep is None:
        log.unlink()
        bvh.unlink()
        folder.rmdir()


if __name__ == "__main__":
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    main()
