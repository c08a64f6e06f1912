"""Does the disagreement of an ensemble's members tell where ``learned`` errs? A measurement.

    python benchmarks/ensemble_spread.py --data ../shared/data --models runs/foot-lock \
        --rows ROWS_DIR [-o TABLE.md]

The tenth round (``docs/results/learned/experiments.md``) found no calibration of the network's
sigma and novelty that is honest per content: a fold's model errs on forward walking, which
looks familiar to it, twice as much as on the turns. A third score is tried here: the
*spread* of a deep ensemble (Lakshminarayanan et al. 2017), how far its members' joint
positions part (:func:`imuloco.methods.learned.method.member_spread`), per frame.

Protocols as ``docs/results/generalization/README.md``: ``heldout-contents`` (both
Bandai-Namco sets, 30 clips a folder) and ``cross-dataset`` (the same 60 clips -> 30
``cmu-iclone`` clips, on canonical body parts), right ankle, ``phone`` noise,
``learned[threads=1]``. Each fold's models of ``--seeds`` (0-2; trained as the bench trains them,
kept under ``--models`` as ``FOLD-seedN.npz``, reused when present; ``xd`` for
``cross-dataset``) are averaged into one ensemble (:func:`~imuloco.methods.learned.
method.ensemble`), which reconstructs the fold's test clips simulated with seed 0's test seed
and is measured as the bench measures (:func:`imuloco.lab.bench.measure`). Its rows are
kept as bench result folders (``ROWS_DIR/heldout-contents``, ``ROWS_DIR/cross-dataset``, each
with a ``confidence-learned.npz``; each measured again only when missing), which ``imuloco
calibrate`` reads.

Then, as ``benchmarks/calibration_forms.py`` checks calibrations: every ``heldout-contents``
content's frames predicted by ``imuloco calibrate``'s law fitted on the other seven contents,
``cross-dataset`` by the law fitted on all of ``heldout-contents``, for each set of scores;
prints predicted rms error over actual rms error per content (issue 16's target: within
+-30 %) and Spearman's rank correlation of the two per clip; ``cross-dataset`` against both
of the bench's measures (body parts of the other rig, and the truth retargeted onto the
training skeleton).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from foot_lock import fold_model
from scipy.stats import spearmanr

from imuloco.core.motion import MotionDatabase
from imuloco.io.atomic import atomic_write, atomic_write_text, check_output
from imuloco.lab import confidence as conf
from imuloco.lab.bench import cross_dataset_test, load_data, measure
from imuloco.lab.protocols import folds
from imuloco.methods.base import calibrated_error
from imuloco.methods.learned.method import ensemble
from imuloco.methods.training import TEST_SEED_OFFSET, synthesize

ROWS = "confidence-learned.npz"
SCORE_SETS = (("sigma_m", "novelty"), ("sigma_m", "novelty", "spread_m"),
              ("sigma_m", "spread_m"), ("novelty", "spread_m"), ("spread_m",))


def rows_of(fold: str, train: MotionDatabase, test: MotionDatabase, models: Path,
            seeds: list[int], truths=None) -> conf.Rows:
    """The confidence rows of the ensemble of one fold's models of ``seeds`` (scores
    ``sigma_m``, ``novelty`` and ``spread_m``) on the test clips simulated with seed 0's test
    seed, as the bench writes them."""
    ens = ensemble([fold_model(fold, train, s, models, {}) for s in seeds])
    test_ex = synthesize(test, ["right_ankle"], "phone", TEST_SEED_OFFSET)
    out = measure(ens, test_ex, progress=True, name=f"{fold}: ensemble of seeds {seeds}",
                  truths=truths)
    parts = out["confidence"]
    for rows in parts:
        n = len(rows["actual_m"])
        rows.update(fold=np.full(n, fold), seed=np.full(n, seeds[0]))
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def save_rows(folder: Path, rows: conf.Rows) -> None:
    """``rows`` as a bench result folder's confidence file."""
    folder.mkdir(parents=True, exist_ok=True)
    with atomic_write(folder / ROWS, "wb") as f:
        np.savez_compressed(f, **rows)


def with_scores(rows: conf.Rows, names: tuple[str, ...]) -> conf.Rows:
    return {k: v for k, v in rows.items()
            if not k.startswith("score_") or k[len("score_"):] in names}


def clip_rank(rows: conf.Rows, pred: np.ndarray, actual: str = "actual_m") -> float:
    """Spearman's rank correlation of predicted and actual rms error per clip."""
    keys = rows["clip"]
    a, p = [], []
    for k in np.unique(keys):
        m = keys == k
        a.append(np.sqrt(np.mean(rows[actual][m] ** 2)))
        p.append(np.sqrt(np.mean(pred[m] ** 2)))
    return float(spearmanr(a, p)[0])


def table(title: str, rows: conf.Rows, preds: dict[str, np.ndarray],
          actual: str = "actual_m") -> list[str]:
    groups = [str(g) for g in np.unique(rows["content"])]
    first = conf.check(rows, next(iter(preds.values())), actual=actual)
    lines = [f"{title}:", "", "| scores | " + " | ".join(groups) +
             " | all | within ±30 % | Spearman per clip |",
             "|---|" + "---:|" * (len(groups) + 3),
             "| actual rms cm | " + " | ".join(f"{r['actual_cm']:.2f}" for r in first)
             + " | | |"]
    for label, pred in preds.items():
        t = conf.check(rows, pred, actual=actual)
        passed = sum(r["within"] for r in t if r["content"] != "all")
        lines.append(f"| {label} | " + " | ".join(f"{r['ratio']:.2f}" for r in t)
                     + f" | {passed} of {len(groups)} | {clip_rank(rows, pred, actual):.2f} |")
    return [*lines, ""]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, required=True, help="the shared data folder")
    ap.add_argument("--models", type=Path, required=True, help="where fold models are kept")
    ap.add_argument("--seeds", default="0,1,2", help="the members' seeds")
    ap.add_argument("--rows", type=Path, required=True,
                    help="folder for the per-frame rows (reused when present)")
    ap.add_argument("-o", "--out", type=Path, help="also write the tables here")
    args = ap.parse_args()
    if args.out:
        check_output(args.out)
    seeds = [int(s) for s in args.seeds.split(",")]
    held_dir, cross_dir = args.rows / "heldout-contents", args.rows / "cross-dataset"
    missing = [d for d in (held_dir, cross_dir) if not (d / ROWS).exists()]
    if missing:
        db = load_data([args.data / "bandai-namco-2", args.data / "bandai-namco-1"], limit=30,
                       progress=True)
    if held_dir in missing:
        parts = [rows_of(f, tr, te, args.models, seeds)
                 for f, tr, te in folds(db, "heldout-contents")]
        save_rows(held_dir, {k: np.concatenate([p[k] for p in parts]) for k in parts[0]})
    if cross_dir in missing:
        test, truths = cross_dataset_test(db, [args.data / "cmu-iclone"], limit=30,
                                          progress=True)
        save_rows(cross_dir, rows_of("xd", db, test, args.models, seeds, truths))
    held, cross = conf.load_rows([held_dir]), conf.load_rows([cross_dir])
    preds_h, preds_x = {"uncalibrated sigma": held["score_sigma_m"]}, {
        "uncalibrated sigma": cross["score_sigma_m"]}
    for names in SCORE_SETS:
        label = " + ".join(names)
        h, x = with_scores(held, names), with_scores(cross, names)
        preds_h[label] = conf.crossfit(h)
        cal = conf.fit(h, "all of heldout-contents")
        preds_x[label] = calibrated_error(cal, {n: x[f"score_{n}"] for n in names})
        print(label, cal["coef"], flush=True)
    lines = [*table("heldout-contents (each content left out of its calibration)", held,
                    preds_h),
             *table("cross-dataset (calibrated on all of heldout-contents)", cross, preds_x),
             *table("cross-dataset, against the truth retargeted onto the training skeleton "
                    "(its floor is zero)", cross, preds_x, "actual_retargeted_m")]
    text = "\n".join(lines)
    print(text)
    if args.out:
        atomic_write_text(args.out, text)


if __name__ == "__main__":
    main()
