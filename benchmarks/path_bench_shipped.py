"""The bench's path and skate figures of the shipped models' animations. A measurement.

    python benchmarks/path_bench_shipped.py [--data ../shared/data] [--limit 2]
        [--placements right_ankle,right_foot,lower_back] [--methods learned,ridge] [-o TABLE.md]

For ``--limit`` clips of each walking content of ``bandai-namco-1`` (walk, walk-back,
walk-left, walk-right) and of ``bandai-namco-2``'s ``heldout-styles`` walks, simulates the test
recording exactly as ``imuloco bench run`` does (phone noise, seed ``TEST_SEED_OFFSET``) and
measures it with the bench's own :func:`imuloco.lab.bench.measure`: the path of the animation
``imuloco reconstruct`` writes (``path_*``), of the method's raw root (``path_raw_*``), and the
animation's MPJPE and foot skate against the truth's skate. ``learned`` is the shipped model of
the placement, which was trained on every clip here: these figures show the path follower on
the shipped product, not a held-out score (``imuloco bench run`` trains per fold for that).
``ridge`` is fitted on the clips of ``bandai-namco-2`` that are not tested here.
Prints a markdown table: per placement, method and content the clip count, the distance
ratio's mean, the mean absolute distance, stride and end-point errors (animation / raw root),
the animation's MPJPE, its skate and the truth's.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from imuloco.app.pipeline import shipped_model
from imuloco.io.database import load_database
from imuloco.lab.bench import aggregate, measure
from imuloco.lab.protocols import HELDOUT_STYLES
from imuloco.methods import get_method, load_model
from imuloco.methods.training import TEST_SEED_OFFSET, synthesize

CONTENTS = ("walk", "walk-back", "walk-left", "walk-right")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="../shared/data")
    ap.add_argument("--limit", type=int, default=2)
    ap.add_argument("--placements", default="right_ankle,right_foot,lower_back")
    ap.add_argument("--methods", default="learned,ridge")
    ap.add_argument("-o", "--out", default=None)
    args = ap.parse_args()
    bn1 = load_database(Path(args.data) / "bandai-namco-1")
    bn2 = load_database(Path(args.data) / "bandai-namco-2")
    pick = [i for c in CONTENTS for i in [k for k, lab in enumerate(bn1.labels)
                                          if lab.get("content") == c][:args.limit]]
    styles = [k for k, lab in enumerate(bn2.labels) if lab.get("content") == "walk"
              and lab.get("style") in HELDOUT_STYLES][:args.limit]
    tests = [(bn1.subset(pick), None), (bn2.subset(styles), "styles:walk")]
    lines = [("| placement | method | clips | n | distance ratio | distance MAE % (raw) | "
              "stride MAE % (raw) | end-point % (raw) | MPJPE cm | skate cm/s | truth's skate |"),
             "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for placement in args.placements.split(","):
        for name in args.methods.split(","):
            if name == "learned":
                method = load_model(shipped_model("learned", placement))
            else:
                train = bn2.subset([k for k in range(len(bn2)) if k not in set(styles)])
                method = get_method(name).fit(train, [placement], "phone", 0)
            clips = []
            for db, label in tests:
                ex = synthesize(db, [placement], "phone", TEST_SEED_OFFSET)
                for c in measure(method, ex)["clips"]:
                    clips.append({**c, "motion_type": label or c["motion_type"]})
            for mtype in dict.fromkeys(c["motion_type"] for c in clips):
                a = aggregate([c for c in clips if c["motion_type"] == mtype])

                def f(key: str, fmt: str = "{:.1f}", a: dict = a) -> str:
                    return "–" if a.get(key) is None else fmt.format(a[key])

                lines.append(
                    f"| {placement} | {name} | {mtype} | {a['n_clips']} | "
                    f"{f('path_distance_ratio', '{:.2f}')} ({f('path_raw_distance_ratio', '{:.2f}')}) | "
                    f"{f('path_distance_mae_pct')} ({f('path_raw_distance_mae_pct')}) | "
                    f"{f('path_stride_mae_pct')} ({f('path_raw_stride_mae_pct')}) | "
                    f"{f('path_end_point_error_pct')} ({f('path_raw_end_point_error_pct')}) | "
                    f"{f('animation_mpjpe_cm', '{:.2f}')} | {f('animation_foot_skate_cm_s')} | "
                    f"{f('foot_skate_gt_cm_s')} |")
            print(lines[-1], flush=True)
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        Path(args.out).write_text(text)


if __name__ == "__main__":
    main()
