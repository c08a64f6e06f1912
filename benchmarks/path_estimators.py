"""How far each path estimator's path is from the truth's, on virtual sensors. A measurement.

    python benchmarks/path_estimators.py [--data ../shared/data] [--limit 8] [--seeds 0]
        [--noise phone] [--placements right_ankle,left_ankle,right_foot,lower_back]
        [-o TABLE.md]

Simulates each placement's sensor (:func:`imuloco.sensors.simulate.simulate`, the ``phone``
noise model: jitter, biases, misplacement) on the test clips of ``heldout-contents`` (every
content of ``bandai-namco-1`` and ``bandai-namco-2``: the estimators train on nothing, so every
clip is unseen) and ``cross-dataset`` (``cmu-iclone``), runs the placement's estimator
(:mod:`imuloco.paths`) and compares its path with the motion's own
(:func:`imuloco.paths.truth.path_of_motion`, :mod:`imuloco.paths.metrics`). Prints per
protocol, placement and content the mean absolute error of the distance walked and of the
mean stride length (per cent), the stride's in metres and the mean end-point error (per cent
of the distance walked), and how many clips gave no path. ``--limit`` clips per content and
dataset (evenly spread), the walker's height from the skeleton.

With ``--real-shin``, only the real ``realworld-shin`` walk (no reference): the shank-pivot
path's stride, cadence and speed beside the shank's swing read off the raw gyroscope
(:func:`imuloco.measures.gait.signal_swing`, degrees per stride) and the stride a pendulum
leg of that swing would take, ``2 x leg x sin(swing / 2)`` (leg 0.53 x the default height):
a consistency check, nothing fitted.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

from imuloco.io.database import load_database
from imuloco.lab.protocols import HELDOUT_CONTENTS
from imuloco.measures.gait import stature
from imuloco.paths.metrics import path_errors, summarize
from imuloco.paths.registry import estimate_path
from imuloco.paths.truth import path_of_motion
from imuloco.sensors.simulate import simulate

PROTOCOLS = {"heldout-contents": ("bandai-namco-1", "bandai-namco-2"),
             "cross-dataset": ("cmu-iclone",)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="../shared/data")
    ap.add_argument("--limit", type=int, default=8)
    ap.add_argument("--seeds", default="0")
    ap.add_argument("--noise", default="phone")
    ap.add_argument("--placements", default="right_ankle,left_ankle,right_foot,lower_back")
    ap.add_argument("-o", "--out", default=None)
    ap.add_argument("--real-shin", action="store_true")
    args = ap.parse_args()
    if args.real_shin:
        real_shin(Path(args.data))
        return
    placements = args.placements.split(",")
    seeds = [int(s) for s in args.seeds.split(",")]
    rows: dict[tuple[str, str, str], list[dict]] = defaultdict(list)
    failed: dict[tuple[str, str, str], int] = defaultdict(int)
    for protocol, folders in PROTOCOLS.items():
        for folder in folders:
            path = Path(args.data) / folder
            if not path.is_dir():
                print(f"skipping {path}: absent", file=sys.stderr)
                continue
            contents = list(HELDOUT_CONTENTS) if protocol == "heldout-contents" else [None]
            for content in contents:
                db = load_database(path, content=[content] if content else None,
                                   limit=args.limit, progress=False)
                for motion, labels in db:
                    if motion.duration < 2.0:
                        continue
                    truth = path_of_motion(motion)
                    height = stature(motion.skeleton)
                    name = content or labels.get("content") or "walk"
                    for seed in seeds:
                        rec = simulate(motion, placements, noise=args.noise, seed=seed)
                        for p in placements:
                            est = estimate_path(rec.select([p]), p, height)
                            key = (protocol, p, name)
                            if not est.strides:
                                failed[key] += 1
                            rows[key].append(path_errors(est, truth))
    head = ("| protocol | placement | content | clips | no path | distance MAE % | "
            "stride MAE % | stride MAE m | end-point error % |")
    lines = [head, "|---|---|---|---:|---:|---:|---:|---:|---:|"]
    by_placement: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for key in sorted(rows):
        s = summarize(rows[key])
        by_placement[key[:2]] += rows[key]
        lines.append(_line(key, s, failed[key]))
    for key in sorted(by_placement):
        s = summarize(by_placement[key])
        nf = sum(v for k, v in failed.items() if k[:2] == key)
        lines.append(_line((*key, "**all**"), s, nf))
    table = "\n".join(lines)
    print(table)
    if args.out:
        Path(args.out).write_text(table + "\n")


def real_shin(data: Path) -> None:
    """The real shin walk's path beside its swing (module docstring)."""
    from imuloco.core.recording import Recording
    from imuloco.measures.gait import signal_cadence, signal_swing
    from imuloco.paths.shank import DEFAULT_HEIGHT_M, ShankPivot
    from imuloco.sensors.reallog import read_log

    rec, _ = read_log(data / "realworld-shin" / "acc_walking_shin.csv", placement="right_ankle")
    k = (rec.times > rec.times[0] + 10) & (rec.times < rec.times[-1] - 10)  # the walk
    rec = Recording(rec.times[k], rec.acc[k], rec.gyro[k], list(rec.placements))
    path = ShankPivot().estimate(rec, "right_ankle")
    lengths = np.array([s.length_m for s in path.strides])
    swing = signal_swing(rec)
    leg = 0.53 * DEFAULT_HEIGHT_M  # hip to floor, Winter 2009 Fig. 4.1
    dur = path.times_s[-1] - path.times_s[0]
    print(f"realworld-shin: {dur:.0f} s, {len(lengths)} strides, stride mean "
          f"{lengths.mean():.3f} m (median {np.median(lengths):.3f}, IQR "
          f"{np.percentile(lengths, 25):.3f}-{np.percentile(lengths, 75):.3f}), distance "
          f"{path.distance_m():.1f} m, speed {path.distance_m() / dur:.2f} m/s, cadence "
          f"{signal_cadence(rec):.1f} steps/min; shank swing {swing:.1f} deg per stride, a "
          f"pendulum leg of {leg:.2f} m: {2 * leg * np.sin(np.radians(swing) / 2):.3f} m")


def _line(key: tuple[str, str, str], s: dict, failed: int) -> str:
    def f(v: float, d: int = 1) -> str:
        return "-" if not math.isfinite(v) else f"{v:.{d}f}"

    return (f"| {key[0]} | {key[1]} | {key[2]} | {int(s['clips'])} | {failed} | "
            f"{f(s['distance_mae_pct'])} | {f(s['stride_mae_pct'])} | "
            f"{f(s['stride_mae_m'], 3)} | {f(s['end_point_error_pct'])} |")


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
