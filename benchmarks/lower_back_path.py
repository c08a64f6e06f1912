"""Where the lower back's path loses its distance on real walks. A measurement.

    python benchmarks/lower_back_path.py [--data ../shared/data/real-imu] [--limit N]
        [--edge-steps 0.5]

For every bout of ``ipol-gait`` (10 m each) and ``mobilise-d-lab`` (INDIP's walking bouts),
the ``lower-back-steps`` path (:mod:`imuloco.paths.lowerback`) scored as ``imuloco bench
real`` scores it (:func:`imuloco.lab.real.evaluate_path`: the pelvis's distance inside the
reference's bout window, the path's strides inside it against the reference's mean), and
the error split in two:

- the stride model: the path's mean stride against the reference's (Zijlstra's pendulum
  with Mobilise-D's factor, on the sensor's height from ``--height``);
- the path itself: the distance error once the stride error is divided out
  (``distance ratio / stride ratio - 1``): steps missed or found at the bout's edges, the
  rhythm, the start and the stop;

and the steps: the contacts of the path's strides inside the window against the
reference's contacts. Prints the
mean absolute and mean signed errors per data set and bout (ipol-gait's first bout starts
from standing and ends at the U-turn, the second starts after it and ends standing).
Nothing is fitted: the estimator runs as a user runs it, with the reference's body height.
"""

from __future__ import annotations

import argparse
import warnings
from collections import defaultdict
from pathlib import Path

import numpy as np

from imuloco.io.realimu import find_datasets, read_trials
from imuloco.lab.real import IC_TOLERANCE_S
from imuloco.measures.sensorgait import L5_HEIGHT_RATIO
from imuloco.paths.base import BodyPath
from imuloco.paths.lowerback import LowerBackSteps
from imuloco.paths.metrics import walked_distance


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="../shared/data/real-imu")
    ap.add_argument("--limit", type=int, default=None)
    ap.add_argument("--edge-steps", type=float, default=0.5)
    args = ap.parse_args()
    estimator = LowerBackSteps(edge_steps=args.edge_steps)
    rows: dict[tuple[str, int], list[dict]] = defaultdict(list)
    for layout, folder in find_datasets(Path(args.data)):
        for trial in read_trials(folder, layout, args.limit):
            if "lower_back" not in trial.recording.placements:
                continue
            ref = trial.reference
            height = ref.height_m if np.isfinite(ref.height_m) else None
            if np.isfinite(ref.sensor_height_m):  # as sensor_gait: the measured sensor height
                height = ref.sensor_height_m / L5_HEIGHT_RATIO
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                path = estimator.estimate(trial.recording.select(["lower_back"]), "lower_back",
                                          height)
            contacts = np.array(sorted({f.time_s for f in path.footfalls}))
            ref_ic = np.sort(np.concatenate(list(ref.initial_contacts.values())))
            for k, b in enumerate(ref.bouts):
                if not (np.isfinite(b.distance_m) and path.strides):
                    continue
                keep = (path.times_s >= b.start) & (path.times_s <= b.end)
                dist = walked_distance(BodyPath(path.times_s[keep], path.root_xy[keep], None,
                                                [], [], path.source, ""))
                inside = [s.length_m for s in path.strides if s.start_s >= b.start -
                          IC_TOLERANCE_S and s.end_s <= b.end + IC_TOLERANCE_S]
                if not inside or not np.isfinite(b.stride_length_m):
                    continue
                d, s = dist / b.distance_m, float(np.mean(inside)) / b.stride_length_m
                rows[(trial.dataset, k if layout == "ipol-gait" else 0)].append({
                    "distance": 100 * (d - 1), "stride": 100 * (s - 1),
                    "path": 100 * (d / s - 1),
                    "steps": int(np.sum((contacts >= b.start) & (contacts <= b.end))
                                 - np.sum((ref_ic >= b.start) & (ref_ic <= b.end)))})
    print("| data set | bout | bouts | distance MAE % (signed) | stride MAE % (signed) | "
          "path alone MAE % (signed) | steps found - reference (mean) |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for (dataset, k), rs in sorted(rows.items()):
        print(f"| {dataset} | {k} | {len(rs)} | {_mae(rs, 'distance')} | {_mae(rs, 'stride')} | "
              f"{_mae(rs, 'path')} | {np.mean([r['steps'] for r in rs]):+.2f} |")


def _mae(rows: list[dict], key: str) -> str:
    """Mean absolute and (in brackets) mean signed value of ``key`` over ``rows``."""
    v = np.array([r[key] for r in rows])
    return f"{np.abs(v).mean():.1f} ({v.mean():+.1f})"


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
