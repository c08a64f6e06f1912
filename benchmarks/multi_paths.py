"""One sensor's path against two sensors' fused path (imuloco.paths.registry.fuse_paths), on
virtual sensors. A measurement.

    python benchmarks/multi_paths.py [--data DIR[,DIR]] [--limit N] [--seeds 0,1]

Simulates both feet (``right_foot,left_foot``: two zero-velocity tracks) and both shins
(``right_ankle,left_ankle``: two shank pivots) with ``phone`` noise on the clips (default: the
bundled sample; ``--limit`` clips per folder), estimates the path from the right sensor alone
and from both (fused), and prints the mean absolute error of the distance walked and of the
mean stride (per cent) and the mean end-point error (per cent of the distance walked) against
the motion's own path (:func:`imuloco.paths.truth.path_of_motion`), with the clips that gave
no path.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from imuloco.errors import ImulocoError
from imuloco.io.database import load_sample
from imuloco.lab.bench import load_data
from imuloco.measures.gait import stature
from imuloco.paths.metrics import path_errors
from imuloco.paths.registry import estimate_path
from imuloco.paths.truth import path_of_motion
from imuloco.sensors.simulate import simulate

PAIRS = (("right_foot", "left_foot"), ("right_ankle", "left_ankle"))
KEYS = ("distance_error_pct", "stride_error_pct", "end_point_error_pct")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None)
    ap.add_argument("--limit", type=int, default=None)
    ap.add_argument("--seeds", default="0")
    args = ap.parse_args()
    db = load_sample() if args.data is None else load_data(args.data.split(","), args.limit)
    seeds = [int(s) for s in args.seeds.split(",")]
    print(f"{len(db)} clips, seeds {seeds}; mean |error| %: distance, stride, end point")
    for pair in PAIRS:
        rows: dict[str, list[list[float]]] = {"one": [], "both": []}
        failed = {"one": 0, "both": 0}
        for clip in db.clips:
            truth = path_of_motion(clip)
            height = stature(clip.skeleton)
            for seed in seeds:
                rec = simulate(clip, list(pair), noise="phone", seed=seed)
                for key, r in (("one", rec.select([pair[0]])), ("both", rec)):
                    try:
                        e = path_errors(estimate_path(r, pair[0], height), truth)
                    except ImulocoError:
                        failed[key] += 1
                        continue
                    rows[key].append([abs(e[k]) for k in KEYS])
        for key, vals in rows.items():
            m = np.nanmean(np.array(vals), axis=0) if vals else [math.nan] * 3
            name = pair[0] if key == "one" else "+".join(pair)
            print(f"{name:24s} " + "  ".join(f"{v:6.1f}" for v in m)
                  + f"   ({len(vals)} paths, {failed[key]} failed)")


if __name__ == "__main__":
    main()
