"""How much of a ground truth's jitter is motion? A measurement on the shared motion.

    python benchmarks/truth_jitter.py --data ../shared/data [--models DIR]

Issue 16 asks a reconstruction's jitter (mean jerk, :func:`imuloco.measures.metrics.jerk`) to be
within +-20 % of its ground truth's. On ``cross-dataset`` the CMU truth's is twice
Bandai-Namco's for the same walking. Prints, per content, the jitter of the canonical body parts
of each data set's ground truth (30 clips a folder, at the training set's 30 fps; ``cmu-iclone``
also at its own 60 fps) as recorded and after a zero-phase low-pass at 6 and 10 Hz
(scipy's 4th-order Butterworth, ``sosfiltfilt``; 6 Hz is the usual cutoff for gait
kinematics, Winter 2009). With ``--models``: the ``xd-seed0.npz`` network there
(``benchmarks/ensemble_spread.py``'s ``cross-dataset`` one) and its ``walk``, ``run`` and
``walk-back`` ``heldout-contents`` networks, their reconstructions' jitter against their truth's
at each cutoff, on the parts as ``bench`` aligns them (:func:`imuloco.measures.metrics.
part_errors`), seed 0's test signals.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from foot_lock import fold_model
from scipy.signal import butter, sosfiltfilt

from imuloco.core.bodymap import PARTS
from imuloco.core.motion import MotionDatabase
from imuloco.core.retarget import resampled
from imuloco.lab.bench import load_data
from imuloco.lab.protocols import folds
from imuloco.measures.metrics import jerk, part_errors
from imuloco.methods.training import TEST_SEED_OFFSET, synthesize

CUTOFFS = (None, 6.0, 10.0)  # Hz; None: as recorded
MIN_FRAMES = 30  # shorter clips are left out (the filter's padding needs a second of motion)


def jitter(positions: np.ndarray, fps: float, cutoff: float | None) -> float:
    """Mean jerk (m/s^3) of positions (T, P, 3), low-passed at ``cutoff`` Hz first."""
    if cutoff is not None:
        positions = sosfiltfilt(butter(4, cutoff, fs=fps, output="sos"), positions, axis=0)
    return float(jerk(positions, fps).mean())


def row(label: str, values: np.ndarray) -> str:
    return f"| {label} | " + " | ".join(f"{v:.0f}" for v in values) + " |"


def truths(name: str, db: MotionDatabase) -> list[str]:
    by: dict[str, list[list[float]]] = {}
    for clip, lab in zip(db.clips, db.labels):
        if clip.num_frames >= MIN_FRAMES:
            p = clip.part_positions(list(PARTS))
            by.setdefault(lab.get("content") or "", []).append(
                [jitter(p, clip.fps, c) for c in CUTOFFS])
    return [row(f"{name}, {k} ({len(v)} clips)", np.mean(v, axis=0)) for k, v in sorted(by.items())]


def reconstructions(label: str, method, test: MotionDatabase) -> str:
    out = []
    for ex in synthesize(test, ["right_ankle"], "phone", TEST_SEED_OFFSET):
        if ex.motion.num_frames >= MIN_FRAMES:
            rec = method.reconstruct_signals_full(ex.signals).motion
            _, truth, recon, _, _ = part_errors(ex.motion, rec)
            out.append([jitter(p, rec.fps, c) for c in CUTOFFS for p in (truth, recon)])
    v = np.mean(out, axis=0)
    cells = [f"{v[2 * k + 1]:.0f} / {v[2 * k]:.0f} ({v[2 * k + 1] / v[2 * k] - 1:+.0%})"
             for k in range(len(CUTOFFS))]
    return f"| {label} | " + " | ".join(cells) + " |"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, required=True, help="the shared data folder")
    ap.add_argument("--models", type=Path, help="a folder of FOLD-seed0.npz networks")
    args = ap.parse_args()
    lab = load_data([args.data / "bandai-namco-2", args.data / "bandai-namco-1"], limit=30,
                    progress=False)
    cmu = load_data([args.data / "cmu-iclone"], limit=30, progress=False)
    cmu30 = MotionDatabase([resampled(c, float(lab.clips[0].fps)) for c in cmu.clips], cmu.labels)
    print("| ground truth, content | as recorded | 6 Hz | 10 Hz |\n|---|---:|---:|---:|")
    for line in [*truths("Bandai-Namco", lab), *truths("cmu-iclone", cmu30),
                 *truths("cmu-iclone at 60 fps", cmu)]:
        print(line)
    if args.models is None:
        return
    print("\n| network: reconstruction / truth | as recorded | 6 Hz | 10 Hz |\n"
          "|---|---:|---:|---:|")
    print(reconstructions("cross-dataset", fold_model("xd", lab, 0, args.models, {}), cmu30),
          flush=True)
    for fold, train, test in folds(lab, "heldout-contents"):
        if fold in ("walk", "run", "walk-back"):
            print(reconstructions(f"heldout-contents, {fold}",
                                  fold_model(fold, train, 0, args.models, {}), test), flush=True)


if __name__ == "__main__":
    main()
