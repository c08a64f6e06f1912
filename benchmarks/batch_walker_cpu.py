"""CPU seconds a batch worker spends on one 60 s walker, once its model is loaded.

``imuloco bench --batch N`` measures this on dask clusters; on a machine too loaded for its
clusters to start in time this runs the same task function (:func:`imuloco.app.batch.
reconstruct_one`) in one process, one thread: a first walker (the model loaded, the stack
imported, numba's lock kernel loaded) untimed, then ``N`` walkers timed by this process's CPU
time (user + system). Usage: ``python benchmarks/batch_walker_cpu.py [N] [placement]``.
"""

from __future__ import annotations

import hashlib
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

from imuloco.app.batch import reconstruct_one
from imuloco.app.pipeline import shipped_model
from imuloco.lab.speed import walk_log


def main(n: int = 3, placement: str = "right_ankle") -> None:
    model = shipped_model("learned", placement).read_bytes()
    sha = hashlib.sha256(model).hexdigest()
    with tempfile.TemporaryDirectory() as tmp:
        logs = [walk_log(placement, 60.0, Path(tmp) / f"w{i}.csv", seed=10 * i)
                for i in range(n + 1)]
        cpu = []
        for i, log in enumerate(logs):
            t0 = time.process_time()
            out = reconstruct_one(str(log), tmp, f"w{i}", sha, model, placement)
            cpu.append(time.process_time() - t0)
            assert "error" not in out["row"] or not out["row"]["error"], out["row"]
        print(f"{placement}: first walker {cpu[0]:.2f} CPU s (loading), then "
              + ", ".join(f"{c:.2f}" for c in cpu[1:]) + f" CPU s per 60 s walker "
              f"(mean {sum(cpu[1:]) / n:.2f}); load {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 3,
         sys.argv[2] if len(sys.argv) > 2 else "right_ankle")
