"""How shipped-style model files do in and out of the lab they were trained on (issue 16).

For each model file (``--models``, comma separated; ``shipped``: the shipped right-ankle
model), one phone at the right ankle, ``phone`` noise, test seeds (1000 + the clip's):

- ``lab``: the ``bandai-namco-2`` clips every such model holds out for its validation curve
  (5 % by CRC32 of the name, :meth:`imuloco.methods.learned.method.Learned._validation_split`);
- ``bandai-namco-1``: ``--limit`` clips of its styles (none in ``bandai-namco-2``) and contents
  (adds dash, walking backwards, side steps), MPJPE and foot skate (ground truth's beside it);
- ``cmu-iclone``: other people on another rig, compared on canonical body parts as
  ``bench --split cross-dataset`` does (retargeting alone scores 5.24 cm there).

MPJPE in cm, frame-weighted, heading-aligned at the first frame as in ``imuloco bench``.
Models trained on a data set are not tested on it: read their row as in-sample there.
"""

from __future__ import annotations

import argparse
import zlib
from pathlib import Path

import numpy as np

SEED = 1000


def _rows(model, examples, parts: bool) -> dict[str, tuple[float, float, float, float]]:
    """Per content: (frames, MPJPE cm, foot skate cm/s, ground truth's skate) summed by frames."""
    from imuloco.evaluate import metrics

    out: dict[str, list[float]] = {}
    for ex in examples:
        gt, full = ex.motion, model.reconstruct_signals(ex.signals)
        n = gt.num_frames
        if parts:
            v, skate, gskate = metrics.evaluate_parts(gt, full)["mpjpe_cm"], np.nan, np.nan
        else:
            rec = metrics.align_heading(full, gt, 0)
            v, skate, gskate = (metrics.mpjpe(gt, rec), metrics.foot_skate(gt, rec),
                                metrics.foot_skate(gt, gt))
        acc = out.setdefault(ex.labels.get("content") or "-", [0.0, 0.0, 0.0, 0.0])
        for i, x in enumerate((n, n * v, n * skate, n * gskate)):
            acc[i] += x
    return {c: (a[0], a[1] / a[0], a[2] / a[0], a[3] / a[0]) for c, a in out.items()}


def _all(rows: dict) -> float:
    n = sum(r[0] for r in rows.values())
    return sum(r[0] * r[1] for r in rows.values()) / n


def main() -> None:
    from imuloco.app.pipeline import shipped_model
    from imuloco.core.motion import MotionDatabase
    from imuloco.core.retarget import resampled
    from imuloco.io.database import load_database
    from imuloco.methods import load_model
    from imuloco.methods.training import synthesize

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=Path("../shared/data"))
    ap.add_argument("--models", required=True)
    ap.add_argument("--limit", type=int, default=80)
    ap.add_argument("-o", "--output", type=Path, default=None)
    args = ap.parse_args()
    lab = load_database(args.data / "bandai-namco-2", progress=False)
    lab = lab.subset([i for i, lab_ in enumerate(lab.labels)
                      if zlib.crc32(lab_["name"].encode()) < 0.05 * 2**32])
    other = load_database(args.data / "bandai-namco-1", limit=args.limit, progress=False)
    cmu = load_database(args.data / "cmu-iclone", progress=False)
    cmu = MotionDatabase([resampled(c, float(lab.clips[0].fps)) for c in cmu.clips], cmu.labels)
    sets = {name: synthesize(db, ["right_ankle"], "phone", SEED)
            for name, db in (("lab", lab), ("bn1", other), ("cmu", cmu))}
    lines = [(f"Test clips: lab {len(lab)} (bandai-namco-2 validation), bandai-namco-1 "
             f"{len(other)}, cmu-iclone {len(cmu)}; right ankle, phone noise, seed {SEED}."), ""]
    bn1_contents: list[str] = []
    table = []
    for name in args.models.split(","):
        model = load_model(shipped_model("learned", "right_ankle") if name == "shipped" else name)
        r = {k: _rows(model, ex, k == "cmu") for k, ex in sets.items()}
        bn1_contents = sorted(r["bn1"])
        table.append((Path(name).name, r))
    head = ("| model | lab | bandai-namco-1 | " + " | ".join(bn1_contents) +
            " | skate: walk-back (truth) | cmu-iclone |")
    lines += [head, "|---|" + "---:|" * (len(bn1_contents) + 4)]
    for name, r in table:
        wb = r["bn1"].get("walk-back", (0, np.nan, np.nan, np.nan))
        lines.append(f"| {name} | {_all(r['lab']):.2f} | {_all(r['bn1']):.2f} | " +
                     " | ".join(f"{r['bn1'][c][1]:.2f}" for c in bn1_contents) +
                     f" | {wb[2]:.1f} ({wb[3]:.1f}) | {_all(r['cmu']):.2f} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.output:
        from imuloco.io.atomic import atomic_write

        with atomic_write(args.output, "w") as f:
            f.write(text)


if __name__ == "__main__":
    main()
