"""How shipped-style model files do in and out of the lab they were trained on (issue 16).

    python benchmarks/model_generalization.py --models shipped,A.npz,... [--data ../shared/data]
                                              [--placement right_ankle]

For each model file (``--models``, comma separated; ``shipped``: the shipped model of the
placement), one sensor at ``--placement`` (default the right ankle), ``phone`` noise, test seed
1000, measured as ``imuloco bench`` measures a test clip (:func:`imuloco.lab.bench.measure`):

- ``lab``: the ``bandai-namco-2`` clips every such model holds out for its validation curve
  (:func:`imuloco.methods.training.held_out_clips`, the method's default share);
- ``bandai-namco-1``: ``--limit`` clips of its styles (none in ``bandai-namco-2``) and contents
  (adds dash, walking backwards, side steps), MPJPE per content and foot skate on walking
  backwards (the ground truth's beside it);
- ``cmu-iclone``: other people on another rig, compared on canonical body parts as
  ``bench --split cross-dataset`` does (retargeting alone scores 5.24 cm there).

MPJPE in cm, frame-weighted. Models trained on a data set are not tested on it: read their row
as in-sample there.
"""

from __future__ import annotations

import argparse
from pathlib import Path

SEED = 1000


def main() -> None:
    from imuloco.app.pipeline import shipped_model
    from imuloco.core.motion import MotionDatabase
    from imuloco.core.retarget import resampled
    from imuloco.io.atomic import atomic_write_text, check_output
    from imuloco.io.database import load_database
    from imuloco.lab.bench import aggregate, measure
    from imuloco.methods import load_model
    from imuloco.methods.training import held_out_clips, synthesize

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=Path("../shared/data"))
    ap.add_argument("--models", required=True)
    ap.add_argument("--limit", type=int, default=80)
    ap.add_argument("--placement", default="right_ankle")
    ap.add_argument("-o", "--output", type=Path, default=None)
    args = ap.parse_args()
    if args.output is not None:
        check_output(args.output)
    lab = held_out_clips(load_database(args.data / "bandai-namco-2", progress=False))
    other = load_database(args.data / "bandai-namco-1", limit=args.limit, progress=False)
    cmu = load_database(args.data / "cmu-iclone", progress=False)
    cmu = MotionDatabase([resampled(c, float(lab.clips[0].fps)) for c in cmu.clips], cmu.labels)
    sets = {name: synthesize(db, [args.placement], "phone", SEED)
            for name, db in (("lab", lab), ("bn1", other), ("cmu", cmu))}
    contents = sorted({c["content"] for c in other.labels})
    lines = [(f"Test clips: lab {len(lab)} (bandai-namco-2 validation), bandai-namco-1 "
              f"{len(other)}, cmu-iclone {len(cmu)}; {args.placement}, phone noise, seed {SEED}."),
             "", "| model | lab | bandai-namco-1 | " + " | ".join(contents) +
             " | skate: walk-back (truth) | cmu-iclone |",
             "|---|" + "---:|" * (len(contents) + 4)]
    for name in args.models.split(","):
        model = load_model(shipped_model("learned", args.placement) if name == "shipped"
                           else name)
        clips = {k: measure(model, ex)["clips"] for k, ex in sets.items()}
        by = {c: aggregate([r for r in clips["bn1"] if r["motion_type"] == c]) for c in contents}
        back = by.get("walk-back", {"foot_skate_cm_s": float("nan"),
                                    "foot_skate_gt_cm_s": float("nan")})
        lines.append(f"| {Path(name).name} | {aggregate(clips['lab'])['mpjpe_cm']:.2f} | "
                     f"{aggregate(clips['bn1'])['mpjpe_cm']:.2f} | " +
                     " | ".join(f"{by[c]['mpjpe_cm']:.2f}" for c in contents) +
                     f" | {back['foot_skate_cm_s']:.1f} ({back['foot_skate_gt_cm_s']:.1f}) | "
                     f"{aggregate(clips['cmu'])['mpjpe_cm']:.2f} |")
        print(lines[-1], flush=True)
    if args.output is not None:
        atomic_write_text(args.output, "\n".join(lines))


if __name__ == "__main__":
    main()
