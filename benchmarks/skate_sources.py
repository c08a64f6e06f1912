"""Where ``learned``'s remaining foot skate comes from, fold by fold. A measurement.

    python benchmarks/skate_sources.py --data ../shared/data --models runs/foot-lock \
        --folds dash,walk [--seed 0] [--flat-turns] [-o OUT.md]

``heldout-contents`` as ``benchmarks/foot_lock.py`` runs it (its fold models, trained when
missing, and test signals), today's ``learned`` post-processing (root pinned, legs locked;
``--flat-turns``: a flat foot's direction left to the motion, the thirteenth round's lock).
Per fold:

- the contact head against the ground truth's contacts (:func:`imuloco.measures.metrics.
  gt_contacts`), heel and toe: precision, recall, the ground truth's and the network's
  contact lengths (frames), and the onsets and offsets matched within 5 frames with their
  mean and median delay (network minus ground truth, ms);
- the foot skate (:func:`imuloco.measures.metrics.foot_skate`'s samples: a foot part's
  horizontal speed between two frames of ground-truth contact, pooled) split by what the
  foot lock did with that foot at the second frame: ``held`` (this part the held one),
  ``held, other part`` (the heel held while the toe is measured, or the reverse), ``landing``
  (held from this frame), ``switch`` (heel to toe or back), ``slip`` (the held point slid,
  :data:`imuloco.methods.postprocess.MAX_HOLD_FEET`), ``lift`` (let go at this frame) and
  ``free`` (the network says the foot is up): each one's share of the samples, mean speed,
  and contribution (share times speed; they add up to the skate), beside the ground
  truth's own speed on the same samples;
- the same split by the sample's place in the ground truth's contact (first, inner, last
  step, or a contact of one step), the reconstruction's and the ground truth's;
- the skate with the lock fed the ground truth's contacts instead of the network's (what a
  perfect contact head would leave).

Skates here are pooled over samples; the bench (and ``foot_lock.py``) weights clips by
frames.
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path

import numpy as np
from foot_lock import fold_model

from imuloco.core.motion import Motion
from imuloco.io.atomic import atomic_write_text
from imuloco.lab.bench import load_data
from imuloco.lab.protocols import folds
from imuloco.measures import metrics
from imuloco.methods import pose
from imuloco.methods.learned.method import PIN_SMOOTHING, pin
from imuloco.methods.postprocess import FootLock
from imuloco.methods.training import TEST_SEED_OFFSET, synthesize
from imuloco.phases.contacts import runs

GT_KEYS = ("left_heel", "right_heel", "left_toe", "right_toe")  # the network's column order
# metrics.FOOT_PARTS in order: (side, the network's column, the lock's kind)
PARTS = ((0, 0, "heel"), (0, 2, "toe"), (1, 1, "heel"), (1, 3, "toe"))
STATES = ("held", "held, other part", "landing", "switch", "slip", "lift", "free")
PLACES = ("first", "inner", "last", "single")
TOLERANCE = 5  # frames within which an event of the network matches the ground truth's


def traced_lock(motion: Motion, c: np.ndarray, **kw) -> tuple[Motion, dict]:
    """:func:`imuloco.methods.postprocess.lock_feet` (``c`` (T, 4) contacts) with what the
    lock did per frame and foot: ``kind`` held ('' none), ``landing``, ``slip``."""
    lock = FootLock(motion.skeleton, motion.fps, PIN_SMOOTHING, **kw)
    legs = lock.legs(motion.rotations, motion.root)
    feet = legs[1][:, lock.sub_feet]
    n = motion.num_frames
    kind = np.full((n, 2), "", dtype=object)
    landing, slip = np.zeros((n, 2), bool), np.zeros((n, 2), bool)
    targets, turns = np.empty((n, 2, 3)), np.empty((n, 2, 4))
    for t in range(n):
        before = [None if h is None else (h[0], h[1].copy()) for h in lock.held]
        targets[t] = lock.targets(feet[t], c[t, :2], c[t, 2:])
        turns[t] = lock.turn
        for s, (now, was) in enumerate(zip(lock.held, before)):
            if now is not None:
                kind[t, s] = now[0]
                landing[t, s] = was is None or was[0] != now[0]
                slip[t, s] = not landing[t, s] and not np.allclose(was[1], now[1])
    rot = lock.bend(motion.rotations, motion.root, targets, legs, turns)
    return (Motion(motion.skeleton, rot, motion.root, motion.fps, motion.name),
            {"kind": kind, "landing": landing, "slip": slip})


def speeds(motion: Motion) -> np.ndarray:
    """(T - 1, 4) horizontal speeds, m/s, of :data:`imuloco.measures.metrics.FOOT_PARTS`."""
    p = motion.part_positions(list(metrics.FOOT_PARTS))[..., [0, 2]]
    return np.linalg.norm(np.diff(p, axis=0), axis=-1) * motion.fps


def delays(truth: np.ndarray, net: np.ndarray) -> tuple[list[int], int]:
    """Delays (frames) of the ground truth's events matched to the network's nearest within
    :data:`TOLERANCE`, and how many found none."""
    out, missed = [], 0
    for t in truth:
        d = net - t
        if len(d) and np.abs(d).min() <= TOLERANCE:
            out.append(int(d[np.argmin(np.abs(d))]))
        else:
            missed += 1
    return out, missed


def state_of(trace: dict, side: int, kind: str) -> np.ndarray:
    """(T - 1,) :data:`STATES` of one foot part's samples."""
    k = trace["kind"][:, side]
    now, was = k[1:] != "", k[:-1] != ""
    land, slip = trace["landing"][1:, side], trace["slip"][1:, side]
    out = np.full(len(now), "free", dtype=object)
    out[now & was] = "held, other part"
    out[now & was & (k[1:] == kind)] = "held"
    out[now & was & land] = "switch"
    out[now & ~was] = "landing"
    out[slip] = "slip"
    out[~now & was] = "lift"
    return out


def place_of(both: np.ndarray) -> np.ndarray:
    """(T - 1,) :data:`PLACES` of samples (``both``: ground-truth contact at both ends)."""
    first = both & ~np.r_[False, both[:-1]]
    last = both & ~np.r_[both[1:], False]
    return np.where(first & last, "single",
                    np.where(first, "first", np.where(last, "last", "inner")))


def measure(method, examples, **lock_kw) -> dict[str, list]:
    """The samples and counts of one fold's test clips."""
    acc: dict[str, list] = defaultdict(list)
    for ex in examples:
        out, vectors = method.pose_vectors(ex.signals)  # as learned decodes them
        c = out.contacts
        pinned = pin(pose.decode(vectors, method.skeleton_, method.fps_), c)
        kw = {"flat_pitch": method.flat_pitch_, **lock_kw}
        rec, trace = traced_lock(pinned, c, **kw)
        g = metrics.gt_contacts(ex.motion)
        truth = np.stack([g[k] for k in GT_KEYS], axis=1)
        oracle = traced_lock(pin(pose.decode(vectors, method.skeleton_, method.fps_),
                                 truth.astype(float)), truth.astype(float), **kw)[0]
        v = {"rec": speeds(rec), "gt": speeds(ex.motion), "oracle": speeds(oracle)}
        for k, (side, col, kind) in enumerate(PARTS):
            gt, net = truth[:, col], c[:, col] > lock_kw.get("threshold", 0.5)
            acc[f"{kind} tp"].append(int((gt & net).sum()))
            acc[f"{kind} fp"].append(int((~gt & net).sum()))
            acc[f"{kind} fn"].append(int((gt & ~net).sum()))
            (gs, ge, gv), (ns, ne, nv) = runs(gt), runs(net)
            acc[f"{kind} gt length"] += list((ge - gs)[gv])
            acc[f"{kind} net length"] += list((ne - ns)[nv])
            for name, a, b in (("onset", gs[gv], ns[nv]), ("offset", ge[gv], ne[nv])):
                d, missed = delays(a, b)
                acc[f"{kind} {name}"] += d
                acc[f"{kind} {name} missed"].append(missed)
            both = gt[:-1] & gt[1:]
            acc["state"] += list(state_of(trace, side, kind)[both])
            acc["place"] += list(place_of(both)[both])
            for name, s in v.items():
                acc[name] += list(s[both, k] * metrics.CM)
    return acc


def report(fold: str, acc: dict[str, list]) -> list[str]:
    """Markdown lines of one fold's figures."""
    ms = 1000.0 / 30.0
    lines = [f"### {fold}", "", ("| part | precision | recall | GT contact frames, median "
             "(IQR) | network's | onsets matched, delay mean / median ms | offsets matched, "
             "delay mean / median ms |"), "|---|---:|---:|---|---|---|---|"]
    for kind in ("heel", "toe"):
        tp, fp, fn = (sum(acc[f"{kind} {x}"]) for x in ("tp", "fp", "fn"))
        gl, nl = np.array(acc[f"{kind} gt length"]), np.array(acc[f"{kind} net length"])
        ev = []
        for name in ("onset", "offset"):
            d = np.array(acc[f"{kind} {name}"], float)
            total = len(d) + sum(acc[f"{kind} {name} missed"])
            ev.append(f"{len(d)}/{total}, {d.mean() * ms:+.0f} / {np.median(d) * ms:+.0f}")
        lines.append(f"| {kind} | {tp / max(tp + fp, 1):.2f} | {tp / max(tp + fn, 1):.2f} | "
                     f"{np.median(gl):.0f} ({np.percentile(gl, 25):.0f}-"
                     f"{np.percentile(gl, 75):.0f}) | {np.median(nl):.0f} | {ev[0]} | {ev[1]} |")
    rec, gt = np.array(acc["rec"]), np.array(acc["gt"])
    n = len(rec)
    lines += ["", (f"Skate over {n} samples: {rec.mean():.1f} cm/s (ground truth "
              f"{gt.mean():.1f}; the lock on the ground truth's contacts "
              f"{np.mean(acc['oracle']):.1f})."), "",
              "| the lock | share | cm/s | contribution | ground truth's cm/s |",
              "|---|---:|---:|---:|---:|"]
    for key, names in (("state", STATES), ("place", PLACES)):
        if key == "place":
            lines += ["", ("| place in the GT contact | share | cm/s | contribution | ground "
                      "truth's cm/s (contribution) |"), "|---|---:|---:|---:|---:|"]
        col = np.array(acc[key])
        for name in names:
            m = col == name
            if m.any():
                extra = (f"{gt[m].mean():.1f}" if key == "state" else
                         f"{gt[m].mean():.1f} ({gt[m].sum() / n:.1f})")
                lines.append(f"| {name} | {m.mean():.2f} | {rec[m].mean():.1f} | "
                             f"{rec[m].sum() / n:.1f} | {extra} |")
    return lines + [""]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, required=True, help="the shared data folder")
    ap.add_argument("--models", type=Path, required=True, help="where fold models are kept")
    ap.add_argument("--folds", default="dash,walk")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--flat-turns", action="store_true",
                    help="leave a flat foot's direction to the motion (the old lock)")
    ap.add_argument("-o", "--out", type=Path, help="also write the report here")
    args = ap.parse_args()
    db = load_data([args.data / "bandai-namco-2", args.data / "bandai-namco-1"], limit=30)
    wanted = args.folds.split(",")
    lines = []
    for fold, train, test in folds(db, "heldout-contents"):
        if fold not in wanted:
            continue
        method = fold_model(fold, train, args.seed, args.models, {})
        examples = synthesize(test, ["right_ankle"], "phone", args.seed + TEST_SEED_OFFSET)
        kw = {"hold_flat": False} if args.flat_turns else {}
        lines += report(f"{fold}, seed {args.seed}", measure(method, examples, **kw))
        print("\n".join(lines[-30:]), flush=True)
    if args.out:
        atomic_write_text(args.out, "\n".join(lines))


if __name__ == "__main__":
    main()
