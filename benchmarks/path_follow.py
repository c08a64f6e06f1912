"""The animation before and after following a path, on virtual sensors. A measurement.

    python benchmarks/path_follow.py [--data ../shared/data] [--limit 2]
        [--placements right_ankle,right_foot,lower_back] [-o TABLE.md]

For a few clips of each walking content of ``bandai-namco-1`` (``heldout-contents`` style) and
of its ``heldout-styles`` walks, simulates the placement's sensor (phone noise, seed 0),
reconstructs with the shipped learned model (:func:`imuloco.app.pipeline.reconstruct_recording`)
and compares the motion's own path with the truth's (:func:`imuloco.paths.metrics
.motion_path_errors`): as reconstructed, after :func:`imuloco.paths.follow.follow` of the
placement's estimated path (with and without the legs' IK), and after following the truth's path (the follower alone). Also
the root-relative MPJPE and the foot skate against the truth's own. Prints a markdown table of
means over clips (absolute errors).
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path

import numpy as np

from imuloco.app.pipeline import choose_model, reconstruct_recording
from imuloco.io.database import load_database
from imuloco.lab.protocols import HELDOUT_STYLES
from imuloco.measures.gait import stature
from imuloco.measures.metrics import foot_skate, mpjpe
from imuloco.paths.follow import follow
from imuloco.paths.metrics import motion_path_errors
from imuloco.paths.registry import estimate_path
from imuloco.paths.truth import path_of_motion
from imuloco.sensors.simulate import simulate

CONTENTS = ("walk", "walk-turn-left", "walk-turn-right", "walk-back")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="../shared/data")
    ap.add_argument("--limit", type=int, default=2)
    ap.add_argument("--placements", default="right_ankle,right_foot,lower_back")
    ap.add_argument("-o", "--out", default=None)
    args = ap.parse_args()
    folder = Path(args.data) / "bandai-namco-1"
    sets = {f"contents:{c}": load_database(folder, content=[c], limit=args.limit,
                                           progress=False) for c in CONTENTS}
    styles = load_database(folder, content=["walk"], progress=False)
    keep = [i for i, lab in enumerate(styles.labels) if lab.get("style") in HELDOUT_STYLES]
    sets["styles:walk"] = styles.subset(keep[:2 * args.limit])
    rows: dict[tuple[str, str, str], list[dict]] = defaultdict(list)
    for p in args.placements.split(","):
        method = choose_model("learned", placement=p).method
        for name, db in sets.items():
            for truth, _ in db:
                rec = simulate(truth, [p], noise="phone", seed=0)
                motion, _ = reconstruct_recording(rec, method)
                est = estimate_path(rec, p, stature(truth.skeleton))
                for label, m in (("reconstructed", motion),
                                 ("follows estimate", follow(motion, est)),
                                 ("follows estimate, no leg IK", follow(motion, est, lock=False)),
                                 ("follows truth", follow(motion, path_of_motion(truth)))):
                    n = min(m.num_frames, truth.num_frames)
                    gt, mm = truth.slice(0, n), m.slice(0, n)
                    e = motion_path_errors(mm, gt)
                    rows[(p, name, label)].append({
                        "dist": abs(e["distance_error_pct"]), "stride": abs(e["stride_error_pct"]),
                        "mpjpe": mpjpe(gt, mm), "skate": foot_skate(gt, mm),
                        "skate_gt": foot_skate(gt, gt)})
    head = ("| placement | clips | animation | clips n | distance err % | stride err % | "
            "MPJPE cm | skate cm/s (truth's) |")
    lines = [head, "|---|---|---|---:|---:|---:|---:|---:|"]
    for (p, name, label), r in rows.items():
        mean = {k: float(np.nanmean([x[k] for x in r])) for k in r[0]}
        lines.append(f"| {p} | {name} | {label} | {len(r)} | {mean['dist']:.1f} | "
                     f"{mean['stride']:.1f} | {mean['mpjpe']:.2f} | {mean['skate']:.1f} "
                     f"({mean['skate_gt']:.1f}) |")
    table = "\n".join(lines)
    print(table)
    if args.out:
        Path(args.out).write_text(table + "\n")


if __name__ == "__main__":
    main()
