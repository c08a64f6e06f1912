"""How much foot skating does ``learned``'s leg IK (``lock_feet``) remove where it was worst?
A measurement.

    python benchmarks/foot_lock.py --data ../shared/data --folds walk-back,dash,walk-left,walk \
        --models runs/foot-lock [--seed 0] [-o TABLE.md]
    python benchmarks/foot_lock.py --data ../shared/data --split heldout-styles \
        --params "epochs=5;strap=0.5;incline=15" --models runs/foot-lock [--seed 0]

The ``heldout-contents`` protocol of ``docs/results/generalization/README.md`` (both
Bandai-Namco sets, 30 clips a folder, right ankle, ``phone`` noise, ``learned[threads=1]``
with the bench's seeds; ``--split heldout-styles``: all of ``bandai-namco-2``, ``--params``
added to the method's), fold by fold: each fold's model is trained once (saved under
``--models``, reused when present), and its test clips are reconstructed once; the same
network outputs are then post-processed several ways:

- ``raw``: the decoded pose (the root's height averaged as the model's ``height_smooth``
  says; none in files from before it), nothing pinned;
- ``root pinned``: :func:`imuloco.methods.learned.method.pin`, the root moved so that feet in
  contact do not slide (all ``learned`` did before ``lock_feet``);
- ``root pinned, legs locked (learned's)``: then :func:`imuloco.methods.learned.method.lock`,
  the planted feet held on the floor by leg IK with the root pinning's smoothing, a flat
  foot's direction held too, at the heading it lands with and the model's flat pitch
  (today's ``learned``; a model file from before ``flat_pitch_`` gets the
  :func:`imuloco.phases.contacts.flat_foot_pitch` of the fold's training clips, as
  ``fit`` computes it); ``flat feet at their landing pitch``: the direction it lands with;
  ``flat feet turn``: the flat foot's direction left to the motion (``learned`` of the
  thirteenth round); ``smoothing 1``: today's without smoothing;
- ``legs locked only``: ``lock`` on the raw pose.

Prints per fold MPJPE (cm), foot skate (cm/s) and jitter (m/s³) of each, frame-weighted as the
bench aggregates, with the ground truth's skate and jitter.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits
from tqdm.auto import tqdm

from imuloco.io.atomic import atomic_write_text
from imuloco.lab.bench import load_data
from imuloco.lab.protocols import folds
from imuloco.measures import metrics
from imuloco.methods import get_method, pose
from imuloco.methods.learned.method import PIN_SMOOTHING, lock, pin
from imuloco.methods.modelfile import load_model
from imuloco.methods.postprocess import lock_feet
from imuloco.methods.training import TEST_SEED_OFFSET, synthesize
from imuloco.phases.contacts import flat_foot_pitch

# "flat" stands for the model's flat_pitch_
LOCKS = {"legs locked (learned's)": {"smoothing": PIN_SMOOTHING, "flat_pitch": "flat"},
         "legs locked, flat feet at their landing pitch": {"smoothing": PIN_SMOOTHING},
         "legs locked, flat feet turn": {"smoothing": PIN_SMOOTHING, "hold_flat": False},
         "legs locked, smoothing 1": {"smoothing": 1.0, "flat_pitch": "flat"}}
VARIANTS = ("raw", "root pinned", *(f"root pinned, {k}" for k in LOCKS), "legs locked only")
KEYS = ("mpjpe_cm", "foot_skate_cm_s", "jitter", "foot_skate_gt_cm_s", "jitter_gt")


def fold_model(fold: str, train, seed: int, models: Path, params: dict):
    """The fold's ``learned[threads=1;params]``, trained as the bench trains it, or loaded."""
    tag = "".join(f"-{k}{v}" for k, v in sorted(params.items()))
    path = models / f"{fold}{tag}-seed{seed}.npz"
    if path.exists():
        method = load_model(path)
        if method.flat_pitch_ is None:  # a file from before it: what fit computes
            method.flat_pitch_ = flat_foot_pitch(train.clips)
        return method
    method = get_method("learned", threads=1, seed=seed, **params)
    with threadpool_limits(limits=1):
        method.fit(train, ["right_ankle"], "phone", seed, progress=True)
    models.mkdir(parents=True, exist_ok=True)
    method.save(path)
    return method


def variants(method, signals: np.ndarray):
    """The post-processings of one test clip's network outputs."""
    out, vectors = method.pose_vectors(signals)  # as learned decodes them
    c = out.contacts
    raw = pose.decode(vectors, method.skeleton_, method.fps_)
    pinned = pin(raw, c)
    flat = method.flat_pitch_
    locked = {f"root pinned, {k}": lock_feet(pinned, c[:, :2], c[:, 2:], **{
        a: flat if v == "flat" else v for a, v in kw.items()}) for k, kw in LOCKS.items()}
    return {"raw": raw, "root pinned": pinned, **locked,
            "legs locked only": lock(raw, c, flat)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, required=True, help="the shared data folder")
    ap.add_argument("--folds", default="walk-back,dash,walk-left,walk")
    ap.add_argument("--models", type=Path, required=True, help="where fold models are kept")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--split", choices=("heldout-contents", "heldout-styles"),
                    default="heldout-contents")
    ap.add_argument("--params", default="", help="learned's parameters, as key=value;...")
    ap.add_argument("-o", "--out", type=Path, help="also write the table here")
    args = ap.parse_args()
    from imuloco.methods.registry import parse_method_spec

    params = parse_method_spec(f"learned[{args.params}]")[1] if args.params else {}
    if args.split == "heldout-styles":
        db = load_data([args.data / "bandai-namco-2"], progress=True)
    else:
        db = load_data([args.data / "bandai-namco-2", args.data / "bandai-namco-1"], limit=30,
                       progress=True)
    wanted = args.folds.split(",")
    lines = [("| left-out content | post-processing | MPJPE cm | skate cm/s | jitter m/s³ "
             "| ground truth skate / jitter |"), "|---|---|---:|---:|---:|---|"]
    for fold, train, test in folds(db, args.split):
        if args.split == "heldout-contents" and fold not in wanted:
            continue
        method = fold_model(fold, train, args.seed, args.models, params)
        test_ex = synthesize(test, ["right_ankle"], "phone", args.seed + TEST_SEED_OFFSET)
        rows: dict[str, list[dict]] = {v: [] for v in VARIANTS}
        for ex in tqdm(test_ex, desc=f"{fold}: post-processing", unit="clip"):
            for name, rec in variants(method, ex.signals).items():
                values = metrics.evaluate(ex.motion, metrics.align_heading(rec, ex.motion, 0))
                rows[name].append({"n_frames": ex.motion.num_frames, **values})
        for name in VARIANTS:
            w = np.array([r["n_frames"] for r in rows[name]], float)
            mean = {}
            for k in KEYS:  # clips without a ground-truth contact have no skate (nan)
                v = np.array([r[k] for r in rows[name]], float)
                ok = np.isfinite(v)
                mean[k] = float(np.average(v[ok], weights=w[ok]))
            lines.append(f"| {fold} | {name} | {mean['mpjpe_cm']:.2f} | "
                         f"{mean['foot_skate_cm_s']:.1f} | {mean['jitter']:.0f} | "
                         f"{mean['foot_skate_gt_cm_s']:.1f} / {mean['jitter_gt']:.0f} |")
        print("\n".join(lines[-len(VARIANTS):]), flush=True)
    table = "\n".join(lines) + "\n"
    print(table)
    if args.out:
        atomic_write_text(args.out, table)


if __name__ == "__main__":
    main()
