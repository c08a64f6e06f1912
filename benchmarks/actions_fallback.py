"""What the per-part fallback catches (issue 41): the shipped right-shin model with and without
:func:`imuloco.methods.fallback.apply_fallback`, on the action clips of both Bandai-Namco sets
(each content scored with neutral poses built without it, as ``heldout-actions`` leaves it
out) and on locomotion clips of every ``heldout-contents`` content (no regression), a virtual
phone at the right ankle, ``phone`` noise, test seed 1000. Per content: body-part group errors
against the mean pose, foot skate against the truth's, strides on standing clips, the share of
frames with an error over twice the walking median that are flagged, and the predicted error
against the actual one.

    nice -n 10 python benchmarks/actions_fallback.py [--loco-every 20] [--cache DIR]
"""
from __future__ import annotations

import argparse
import functools
import operator
import pickle
from pathlib import Path

import numpy as np

from imuloco.app.pipeline import shipped_model
from imuloco.io.database import load_database, load_databases
from imuloco.lab.neutral import SHANKS, build_neutral
from imuloco.lab.protocols import HELDOUT_ACTIONS
from imuloco.measures import metrics
from imuloco.measures.strides import stride_rows
from imuloco.methods import get_method, load_model
from imuloco.methods.fallback import apply_fallback
from imuloco.methods.training import synthesize

D = Path(__file__).resolve().parents[1].parent / "shared" / "data"
KEYS = ("mpjpe_cm", "legs_cm", "arms_cm", "trunk_cm", "foot_skate_cm_s")
STANDING = ("bye", "raise-up-both-hands", "raise-up-left-hand", "raise-up-right-hand",
            "wave-both-hands", "wave-left-hand", "wave-right-hand")


def reconstructions(model, examples, cache: Path | None) -> list:
    """The model's reconstructions of ``examples``, each cached by clip name in ``cache`` (our
    own pickles of a previous run of this script, never a user's file)."""
    out = []
    for e in examples:
        path = None if cache is None else cache / f"{e.labels['name']}.pkl"
        if path is not None and path.is_file():
            with open(path, "rb") as f:
                out.append(pickle.load(f))
            continue
        out.append(model.reconstruct_signals_full(e.signals))
        if path is not None:
            cache.mkdir(parents=True, exist_ok=True)
            with open(path, "wb") as f:
                pickle.dump(out[-1], f)
    return out


def score(ex, full) -> dict:
    """One clip's numbers: :data:`KEYS`, the truth's skate, strides, per-frame actual and
    predicted error (m) and flags."""
    gt, rec = ex.motion, metrics.align_heading(full.motion, ex.motion, 0)
    v = metrics.evaluate(gt, rec)
    err = metrics.joint_errors(gt, rec)
    actual = np.sqrt((err[:, 1:] ** 2).mean(axis=1))
    try:
        strides = len(stride_rows(rec))
    except Exception:  # noqa: BLE001 (a clip too short for gait phases: none)
        strides = 0
    return {**{k: v[k] for k in KEYS}, "skate_gt": v["foot_skate_gt_cm_s"],
            "strides": strides, "actual": actual, "pred": np.asarray(full.error_m, float),
            "flag": np.asarray(full.unreliable, bool), "n": gt.num_frames}


def summary(rows: list[dict], limit_m: float) -> dict:
    """Frame-weighted means of :data:`KEYS` and skate, strides summed, the flagged share of
    frames over ``limit_m`` and predicted / actual."""
    n = np.array([r["n"] for r in rows], float)
    out = {k: float(np.average([r[k] for r in rows], weights=n)) for k in (*KEYS, "skate_gt")}
    out["strides"] = int(sum(r["strides"] for r in rows))
    actual = np.concatenate([r["actual"] for r in rows])
    pred = np.concatenate([r["pred"] for r in rows])
    flag = np.concatenate([r["flag"] for r in rows])
    high = actual > limit_m
    out["high_share"] = float(high.mean())
    out["flagged_of_high"] = float(flag[high].mean()) if high.any() else float("nan")
    out["flagged_of_low"] = float(flag[~high].mean()) if (~high).any() else float("nan")
    out["pred_over_actual"] = float(np.nanmean(pred) / actual.mean())
    return out


def line(name: str, s: dict) -> str:
    return (f"| {name} | {s['legs_cm']:.2f} / {s['arms_cm']:.2f} / {s['trunk_cm']:.2f} | "
            f"{s['mpjpe_cm']:.2f} | {s['foot_skate_cm_s']:.1f} ({s['skate_gt']:.1f}) | "
            f"{s['strides']} | {100 * s['flagged_of_high']:.0f} % ({100 * s['high_share']:.0f}"
            f" %) | {s['pred_over_actual']:.2f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--loco-every", type=int, default=20,
                    help="every n-th locomotion clip of each folder")
    ap.add_argument("--cache", type=Path, default=None)
    ap.add_argument("--actions-only", action="store_true",
                    help="only the action clips' fallback rows (the mean pose's and the "
                         "shipped model's do not change with the rule)")
    ap.add_argument("--loco-only", action="store_true", help="only the locomotion clips")
    ap.add_argument("--walk-median-cm", type=float, default=None,
                    help="the walking median error (else measured on the walk clips)")
    args = ap.parse_args()
    acts = load_databases([D / "bandai-namco-1-actions", D / "bandai-namco-2-actions"],
                          progress=False)
    loco = [load_database(D / f, progress=False) for f in ("bandai-namco-2", "bandai-namco-1")]
    loco_db = [db.subset(list(range(0, len(db), args.loco_every))) for db in loco]
    mean_train = load_database(D / "bandai-namco-2", limit=120, progress=False)
    model = load_model(shipped_model("learned", "right_ankle"))
    mean = get_method("mean").fit(mean_train, ["right_ankle"], "phone", 0)

    act_ex = synthesize(acts, ["right_ankle"], "phone", 1000)
    both = synthesize(acts, list(SHANKS), "phone", 1000)  # the neutral's still frames
    loco_ex = [e for db in loco_db for e in synthesize(db, ["right_ankle"], "phone", 1000)]
    walking = [m for db in loco for m, lab in db if lab.get("content") in
               ("walk", "walk-turn-left", "walk-turn-right")][::12]
    fulls = reconstructions(model, act_ex, args.cache)
    print(f"{len(fulls)} action clips reconstructed", flush=True)
    loco_full = [] if args.actions_only else reconstructions(model, loco_ex, args.cache)

    # the walking median error: the threshold of "high error" frames is twice it
    if args.walk_median_cm is None:
        walk_err = np.concatenate([score(e, f)["actual"] for e, f in zip(loco_ex, loco_full)
                                   if e.labels.get("content") == "walk"])
        limit = 2 * float(np.median(walk_err))
    else:
        limit = 2 * args.walk_median_cm / 100
    print(f"walking median error {100 * limit / 2:.2f} cm: high error above "
          f"{100 * limit:.2f} cm")
    print("| content | legs / arms / trunk cm | MPJPE | foot skate (truth) cm/s | strides "
          "| flagged of high (high share) | predicted / actual |")
    print("|---|---|---|---|---|---|---|")
    rows: dict[str, dict[str, list]] = {}
    contents = [c for c in HELDOUT_ACTIONS if any(e.labels.get("content") == c for e in act_ex)
                and not args.loco_only]
    for c in contents:
        keep = [i for i, e in enumerate(act_ex) if e.labels.get("content") != c]
        neutral = build_neutral([both[i] for i in keep], walking,
                                f"without {c}")
        for i, e in enumerate(act_ex):
            if e.labels.get("content") != c:
                continue
            on, _ = apply_fallback(fulls[i], e.signals, "right_ankle", neutral,
                                   novelty_threshold=model.novelty_threshold)
            base = None if args.actions_only else mean.reconstruct_signals_full(e.signals)
            for name, f in (("mean", base), ("shipped", fulls[i]), ("fallback", on)):
                if f is None or args.actions_only and name != "fallback":
                    continue
                if name == "mean":
                    f.error_m, f.unreliable = np.full(e.motion.num_frames, np.nan), \
                        np.zeros(e.motion.num_frames, bool)
                rows.setdefault(name, {}).setdefault(c, []).append(score(e, f))
    for c in ["ALL", "STANDING", *contents] if contents else []:
        for name, by in rows.items():
            sel = (functools.reduce(operator.iadd, by.values(), []) if c == "ALL" else
                   functools.reduce(operator.iadd, (by[k] for k in STANDING if k in by), [])
                   if c == "STANDING" else by[c])
            print(line(f"{c} {name}", summary(sel, limit)))
    if args.actions_only:
        return
    # locomotion: the shipped neutral (all actions) and every locomotion content
    neutral = build_neutral(both, walking, "all")
    lrows: dict[str, dict[str, list]] = {}
    for e, f in zip(loco_ex, loco_full):
        on, _ = apply_fallback(f, e.signals, "right_ankle", neutral,
                               novelty_threshold=model.novelty_threshold)
        for name, g in (("shipped", f), ("fallback", on)):
            lrows.setdefault(name, {}).setdefault(e.labels.get("content"), []).append(
                score(e, g))
    for c in ["ALL", *sorted(lrows["shipped"])]:
        for name in ("shipped", "fallback"):
            sel = functools.reduce(operator.iadd, lrows[name].values(), []) if c == "ALL" else lrows[name][c]
            print(line(f"loco {c} {name}", summary(sel, limit)))


if __name__ == "__main__":
    main()
