"""Build the neutral poses the per-part fallback moves toward
(``src/imuloco/data/models/neutral_poses.npz``, :mod:`imuloco.methods.fallback`): the standing
pose from the frames of the Bandai-Namco action clips where both virtual shin phones are still,
the walking pose from every frame of the walking clips (walk, walk-turn-left/right) of both
Bandai-Namco locomotion sets, with what each misses per body-part group.

    python benchmarks/build_neutral.py [--shared ../shared/data] [-o FILE]
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from imuloco.data import MODELS_DIR
from imuloco.io.database import load_database, load_databases
from imuloco.lab.neutral import SHANKS, build_neutral
from imuloco.methods.fallback import ACTIVITIES, GROUPS, NEUTRAL_FILE
from imuloco.methods.training import synthesize

WALKING = ("walk", "walk-turn-left", "walk-turn-right")
SOURCE = ("Bandai-Namco-Research-Motiondataset-1 and -2 (Bandai Namco Research Inc., "
          "CC BY-NC 4.0; Kobayashi et al., arXiv:2306.08861, 2023): standing frames of the "
          "action clips, every frame of the walking clips")


def main() -> None:
    here = Path(__file__).resolve().parents[1]
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--shared", type=Path, default=here.parent / "shared" / "data")
    ap.add_argument("-o", "--out", type=Path, default=MODELS_DIR / NEUTRAL_FILE)
    args = ap.parse_args()
    acts = load_databases([args.shared / "bandai-namco-1-actions",
                           args.shared / "bandai-namco-2-actions"], progress=False)
    walking = [m for f in ("bandai-namco-2", "bandai-namco-1")
               for m, lab in load_database(args.shared / f, progress=False)
               if lab.get("content") in WALKING]
    still = synthesize(acts, list(SHANKS), "phone", 0)
    neutral = build_neutral(still, walking, SOURCE)
    neutral.save(args.out)
    rms = np.sqrt(neutral.sq_error_m2) * 100
    for a, row in zip(ACTIVITIES, rms):
        print(f"{a}: expected error per group (cm-equivalent rms contribution) "
              + ", ".join(f"{g} {v:.2f}" for g, v in zip(GROUPS, row))
              + f"; total {np.sqrt(neutral.sq_error_m2[ACTIVITIES.index(a)].sum()) * 100:.2f}")
    print(f"clearance {neutral.clearance_m * 100:.1f} cm; {len(walking)} walking clips, "
          f"{len(still)} action clips; wrote {args.out}")


if __name__ == "__main__":
    main()
