"""How far a shin phone's leg swings, and the stride the shin model reads: a measurement.

    python benchmarks/shin_stride.py [--data ../shared/data] [--seed 1] [-o TABLE.md]

A shin sensor's gyroscope says, with no model, how far its shank turns in a stride
(:func:`imuloco.measures.gait.signal_swing`). On virtual walks (the right ankle, ``phone``
noise, 50 Hz as the real phone) that swing is compared with the ground truth's shank
(:func:`imuloco.measures.gait.shank_swings`), and a stride-from-swing law (stride over leg
length, linear in the swing) is fitted on ``bandai-namco-2``'s walks and read on
``bandai-namco-1``'s and ``cmu-iclone``'s (other styles, other people). Those two sets are
also read turned (``--tilts``) and with damped accelerations (``--damped``), as the real
phone differs. Then the real ``realworld-shin`` walk: its swing, the stride the law gives on
the model skeleton, and what the shipped ``learned_right_ankle.npz`` reconstructs from it
(both calibration branches; its stride and both shanks' swing), beside the same model on the
virtual walks (which it trained on: in-sample). Last, the real walk with its signals'
amplitude scaled (what the model's stride follows). The real walk has no reference: this is
a consistency check, and the law is fitted on virtual walks only, never on the real one.
``--models`` adds other right-ankle model files to the real walk's table (earlier shipped
weights are in git: ``git show REV:src/imuloco/data/models/learned_right_ankle.npz > F``).

    python benchmarks/shin_stride.py --models shipped,A.npz,B.npz
"""

from __future__ import annotations

import argparse
import logging
from collections.abc import Callable
from pathlib import Path

import numpy as np
from shin_novelty import changed, dynamics, real_walk

SETS = ("bandai-namco-2", "bandai-namco-1", "cmu-iclone")
MIN_SECONDS = 4.0  # a signal's cadence needs two of the slowest strides (signal_cadence)


def walks(data: Path, name: str):
    """The walking clips of one shared motion set long enough for a cadence (most of
    ``cmu-iclone``'s walks are 2-4 s)."""
    from imuloco.lab.bench import load_data

    db = load_data(data / name, skip_frames=1 if name == "cmu-iclone" else 0)
    for clip, lab in zip(db.clips, db.labels):
        if lab.get("content") == "walk" and clip.duration >= MIN_SECONDS:
            yield clip


def virtual_rows(data: Path, seed: int, model, change: Callable | None = None,
                 sets: tuple[str, ...] = SETS) -> dict[str, np.ndarray]:
    """Per set, rows (clips, 8): the signal's swing, the truth's right shank swing, the
    truth's stride over its leg length, then the model's stride over the model skeleton's
    leg length, its right and left shank swing, the truth's left shank swing and the
    signal's :func:`inclination`; each recording first mapped by ``change``."""
    from imuloco.core.retarget import resampled
    from imuloco.measures.gait import gait_parameters, shank_swings, signal_swing
    from imuloco.sensors.simulate import simulate

    out = {}
    leg_model = model.skeleton_.leg_length()
    for name in sets:
        rows = []
        for clip in walks(data, name):
            clip = resampled(clip, 30.0)
            rec = simulate(clip, ["right_ankle"], rate=50.0, noise="phone", seed=seed)
            rec = rec if change is None else change(rec)
            rec_motion = model.reconstruct(rec)
            truth, read = shank_swings(clip), shank_swings(rec_motion)
            rows.append([signal_swing(rec), truth["right"],
                         gait_parameters(clip)["stride_length_m"] / clip.skeleton.leg_length(),
                         gait_parameters(rec_motion)["stride_length_m"] / leg_model,
                         read["right"], read["left"], truth["left"], inclination(rec)])
        out[name] = np.array(rows, dtype=np.float64)
    return out


def inclination(rec) -> float:
    """Degrees the shank sensor's mean specific force over the walk lies from its y axis (up
    the shin) about x (its swing axis): the shank's mean walking inclination as the sensor
    reads it (negative: leaning forward), which the still branch of the calibration leaves
    as the walk has it and the walk branch sets to -``WALK_INCLINATION``."""
    a = rec.acc[:, 0].mean(axis=0)
    return float(np.degrees(np.arctan2(a[2], a[1])))


def real_rows(data: Path, model) -> list[tuple[str, dict[str, float]]]:
    """The whole real walk on each calibration branch: the model's gait and shank swings."""
    from imuloco.measures.gait import gait_parameters, shank_swings, signal_swing

    out = []
    for branch, still_s in (("gravity at rest (default)", 1.0), ("the walk's mean force", 1e9)):
        rec = real_walk(data, None, still_s)
        m = model.reconstruct(rec)
        g, swing = gait_parameters(m), shank_swings(m)
        out.append((branch, {"signal swing": signal_swing(rec), "inclination": inclination(rec),
                             "stride / leg": g["stride_length_m"] / model.skeleton_.leg_length(),
                             "stride m": g["stride_length_m"], "speed": g["speed_mps"],
                             "cadence": g["cadence_spm"], "right swing": swing["right"],
                             "left swing": swing["left"],
                             "stance L / R": (g["left_stance_pct"], g["right_stance_pct"])}))
    return out


def scaled_rows(data: Path, model, seconds: float = 240.0) -> list[str]:
    """The real walk's first ``seconds`` (after 10 s) with its signals' amplitude scaled: the
    acceleration's dynamics (:func:`shin_novelty.dynamics`) and the whole gyroscope. Table
    rows: the model's stride and both shanks' swing."""
    from imuloco.measures.gait import gait_parameters, shank_swings

    real = real_walk(data, seconds)
    changes = {"as recorded": real}
    for k in (0.7, 1.4, 2.0):
        changes[f"acceleration dynamics x {k}"] = changed(real, lambda r, k=k: dynamics(r, k))
    for k in (0.8, 1.2):
        changes[f"gyroscope x {k}"] = changed(real, gyro=lambda r, k=k: r.gyro * k)
    lines = []
    for name, rec in changes.items():
        m = model.reconstruct(rec)
        swing = shank_swings(m)
        lines.append(f"| {name} | {gait_parameters(m)['stride_length_m']:.2f} | "
                     f"{swing['right']:.0f} / {swing['left']:.0f} |")
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=Path("../shared/data"))
    ap.add_argument("--seed", type=int, default=1, help="the virtual sensors' noise seed")
    ap.add_argument("--models", default="shipped",
                    help="right-ankle model files for the real walk, comma-separated "
                         "('shipped': the shipped one, also measured on the virtual walks)")
    ap.add_argument("--tilts", default="-12,12",
                    help="degrees the virtual sensors of the other sets are also turned by, as "
                         "a calibration that far off would (-12: the real walk's inclination)")
    ap.add_argument("--damped", default="0.5",
                    help="factors the other sets' virtual accelerations' dynamics are also "
                         "scaled by (a real phone's carry about half the virtual ones')")
    ap.add_argument("-o", "--output", type=Path, help="also write the tables to this file")
    args = ap.parse_args()
    logging.getLogger("imuloco").setLevel(logging.ERROR)  # the real log's gap warnings

    from imuloco.app.pipeline import shipped_model
    from imuloco.methods import load_model

    model = load_model(shipped_model("learned", "right_ankle"))
    leg = model.skeleton_.leg_length()
    rows = virtual_rows(args.data, args.seed, model)
    fit = rows["bandai-namco-2"]
    slope, icpt = np.polyfit(fit[:, 0], fit[:, 2], 1)

    def q(x: np.ndarray) -> str:
        return f"{np.median(x):.2f} [{np.percentile(x, 10):.2f}, {np.percentile(x, 90):.2f}]"

    head = ("set", "walks", "signal swing deg", "inclination deg", "signal / truth's shank swing",
            "truth's stride / leg", "law's stride / truth's",
            "model's stride / truth's (in-sample)", "model's left / right swing",
            "truth's left / right swing")
    lines = [(f"Virtual walks (right ankle, `phone` noise, 50 Hz, seed {args.seed}); median "
             "[10th, 90th percentile]:"), "", "| " + " | ".join(head) + " |",
             "|---|" + "---:|" * (len(head) - 1)]
    from imuloco.methods.learned.train import inclined

    changes = {**{f"turned {t:+g} deg": lambda r, t=t: inclined(r, np.array([t]))
                  for t in (float(x) for x in args.tilts.split(",") if x)},
               **{f"acceleration dynamics x {k:g}": lambda r, k=k: changed(r, lambda q:
                                                                         dynamics(q, k))
                  for k in (float(x) for x in args.damped.split(",") if x)}}
    for label, change in changes.items():
        rows.update({f"{name}, {label}": r for name, r in
                     virtual_rows(args.data, args.seed, model, change, SETS[1:]).items()})
    for name, r in rows.items():
        cells = (name, str(len(r)), q(r[:, 0]), q(r[:, 7]), q(r[:, 0] / r[:, 1]), q(r[:, 2]),
                 q((slope * r[:, 0] + icpt) / r[:, 2]), q(r[:, 3] / r[:, 2]),
                 q(r[:, 5] / r[:, 4]), q(r[:, 6] / r[:, 1]))
        lines.append("| " + " | ".join(cells) + " |")
    corr = np.corrcoef(fit[:, 0], fit[:, 2])[0, 1]
    head = ("model", "calibration", "signal swing deg", "inclination deg", "law's stride m",
            "model's stride m",
            "speed m/s", "cadence", "model's right / left swing deg", "stance % L / R")
    lines += ["", (f"Law (fitted on bandai-namco-2's walks): stride / leg = {slope:.4f} x swing "
              f"{icpt:+.3f}; correlation {corr:.2f}."), "",
              ("The real shin walk (`realworld-shin`, 10 s in to 10 s before its end); lengths "
              f"on the model skeleton (leg {leg:.3f} m):"), "", "| " + " | ".join(head) + " |",
              "|---|---|" + "---:|" * (len(head) - 2)]
    for name in args.models.split(","):
        other = model if name == "shipped" else load_model(name)
        if other.skeleton_.leg_length() != leg:
            raise SystemExit(f"{name}: another skeleton than the shipped model's")
        for branch, v in real_rows(args.data, other):
            cells = (name, branch, f"{v['signal swing']:.1f}", f"{v['inclination']:.1f}",
                     f"{(slope * v['signal swing'] + icpt) * leg:.2f}", f"{v['stride m']:.2f}",
                     f"{v['speed']:.2f}", f"{v['cadence']:.1f}",
                     f"{v['right swing']:.1f} / {v['left swing']:.1f}",
                     "{:.0f} / {:.0f}".format(*v["stance L / R"]))
            lines.append("| " + " | ".join(cells) + " |")
    lines += ["", ("The shipped model on the real walk's first 240 s (after 10 s, default branch) "
              "with its signals' amplitude scaled:"), "",
              "| change | model's stride m | model's right / left swing deg |",
              "|---|---:|---:|", *scaled_rows(args.data, model)]
    text = "\n".join(lines) + "\n"
    print(text)
    if args.output:
        args.output.write_text(text)


if __name__ == "__main__":
    main()
