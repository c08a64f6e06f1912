"""Load test of the live server on 127.0.0.1 (issue #18, "Live server").

    python benchmarks/live_load.py --out docs/results/live [--viewers 100] [--seconds 20]

A server in a child process (the shipped model, no calibration) on a free loopback port; in
this process ``--viewers`` websocket viewers and one phone streaming a simulated walk at real
time, which also sends the abusive messages (a 1 MiB message, 20 x 1000 rows 1e-7 s apart,
2000 messages as fast as it can, a second phone, a viewer that talks). Prints and writes
``load.json``: viewers dropped, poses per second each viewer received, the server's memory
growth, its log lines; then ``dropout.json``: the recovery after 1 s sensor dropouts on
replayed simulated walks (:func:`imuloco.lab.livebench.dropout_recovery`). Linux only (reads
/proc for the server's memory); bounded: one run of ``--seconds``, nine dropout replays.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from imuloco.io.atomic import atomic_write
from imuloco.lab.livebench import dropout_recovery, load_test


def dropouts(threshold_cm: float = 1.0) -> dict:
    from imuloco.app.pipeline import choose_method
    from imuloco.io.database import load_sample
    from imuloco.sensors.simulate import simulate

    method, note = choose_method()
    clips = [c for c in load_sample().clips if c.name in (
        "dataset-2_walk_normal_001", "dataset-2_walk_exhausted_001",
        "dataset-2_walk-turn-right_exhausted_001")]
    runs = []
    for clip in clips:
        rec = simulate(clip, ["right_ankle"], 100.0, "phone", 11)
        for start in (4.5, 5.0, 5.5):
            if rec.times[-1] < start + 1.0 + 2.1:
                continue
            r = dropout_recovery(method, rec.times, rec.acc, rec.gyro, start, 1.0, threshold_cm)
            runs.append({"clip": clip.name, **r.to_json()})
    rec_s = np.array([r["recovery_s"] for r in runs])
    return {"model": note, "threshold_cm": threshold_cm, "runs": len(runs),
            "recovery_s": {"mean": float(rec_s.mean()), "max": float(rec_s.max())},
            "root_offset_m": {"mean": float(np.mean([r["root_offset_m"] for r in runs])),
                              "max": float(np.max([r["root_offset_m"] for r in runs]))},
            "heading_offset_deg": {"mean_abs": float(np.mean(
                [abs(r["heading_offset_deg"]) for r in runs]))},
            "details": runs}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="folder for load.json, dropout.json")
    ap.add_argument("--viewers", type=int, default=100)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--no-abuse", action="store_true", help="the phone only streams")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    load = load_test(args.viewers, args.seconds, abuse=not args.no_abuse)
    with atomic_write(args.out / "load.json", "w") as f:
        f.write(json.dumps(load, indent=1))
    print(json.dumps({k: v for k, v in load.items() if k not in ("server_log", "dropped")},
                     indent=1))
    drop = dropouts()
    with atomic_write(args.out / "dropout.json", "w") as f:
        f.write(json.dumps(drop, indent=1))
    print(json.dumps({k: v for k, v in drop.items() if k != "details"}, indent=1))


if __name__ == "__main__":
    main()
