"""Does retargeting keep a flat foot flat? A measurement on the two rigs of the shared motion.

    python benchmarks/retarget_feet.py --data ../shared/data [--models DIR --seeds 0,1,2]

Bandai-Namco's toe joint sits at the sole, Character Creator's (``cmu-iclone``) inside the foot:
a flat foot's ankle-to-toe direction points 40 and 15 degrees below the floor. Prints, for the
``cross-dataset`` protocol's clips (both Bandai-Namco sets and ``cmu-iclone``, 30 clips a
folder, as ``docs/results/generalization/README.md``):

- the flat-foot pitch (:func:`imuloco.phases.contacts.flat_foot_pitch`) of Bandai-Namco's
  clips, of the CMU clips on their own rig, and of the CMU clips retargeted onto the
  Bandai-Namco skeleton as the bench and training retarget them
  (:func:`imuloco.lab.bench.truth_on_training_rig`); a retargeting that keeps a flat foot
  flat gives the third the first's pitch;
- the parts measure's floor: that retargeted truth scored against the CMU truth on body parts
  (:func:`imuloco.measures.metrics.evaluate_parts`);
- with ``--models``: each ``xd-seedN.npz`` there (``benchmarks/ensemble_spread.py``'s
  ``cross-dataset`` networks) scored as ``bench`` scores it, on the parts and against the
  retargeted truth, on seed 0's test signals.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from foot_lock import fold_model

from imuloco.lab.bench import load_cross_dataset, measure
from imuloco.measures.metrics import evaluate_parts
from imuloco.methods.training import TEST_SEED_OFFSET, synthesize
from imuloco.phases.contacts import flat_foot_pitch

KEYS = ("mpjpe_cm", "mpjpe_retargeted_cm", "upper_retargeted_cm", "lower_retargeted_cm")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, required=True, help="the shared data folder")
    ap.add_argument("--models", type=Path, help="a folder of xd-seedN.npz networks")
    ap.add_argument("--seeds", default="0,1,2", help="the networks' seeds")
    args = ap.parse_args()
    train, test, truths = load_cross_dataset(
        [args.data / "bandai-namco-2", args.data / "bandai-namco-1"], [args.data / "cmu-iclone"],
        limit=30)
    moved = [truths[lab["name"]] for lab in test.labels]
    for label, clips in (("Bandai-Namco", train.clips), ("cmu-iclone on its own rig", test.clips),
                         ("cmu-iclone retargeted onto Bandai-Namco", moved)):
        print(f"flat-foot pitch, {label}: {np.degrees(flat_foot_pitch(clips)):.1f} degrees")
    floor = [evaluate_parts(c, m) for c, m in zip(test.clips, moved)]
    print("the parts measure's floor, cm: " + ", ".join(
        f"{k} {np.mean([f[k] for f in floor]):.2f}" for k in ("mpjpe_cm", "upper_cm", "lower_cm")))
    if args.models is None:
        return
    examples = synthesize(test, ["right_ankle"], "phone", TEST_SEED_OFFSET)
    rows = []
    for seed in (int(s) for s in args.seeds.split(",")):
        clips = measure(fold_model("xd", train, seed, args.models, {}), examples,
                        truths=truths)["clips"]
        rows.append([np.mean([c[k] for c in clips]) for k in KEYS])
        print(f"seed {seed}: " + ", ".join(f"{k} {v:.2f}" for k, v in zip(KEYS, rows[-1])))
    rows = np.array(rows)
    print("mean ± sd over seeds: " + ", ".join(
        f"{k} {m:.2f} ± {s:.2f}" for k, m, s in zip(KEYS, rows.mean(0), rows.std(0, ddof=1))))


if __name__ == "__main__":
    main()
