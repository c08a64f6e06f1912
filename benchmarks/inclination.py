"""How much a shin model's reconstruction depends on the calibration's inclination (issue 16).

    python benchmarks/inclination.py --models shipped,A.npz,... [--data ../shared/data]
        [--angles -15,-8,0,8,15] [-o TABLE.md]

A real phone's up axis comes from ``calibrate``: gravity at rest, or the walk's mean force
turned by a prior. The two can differ by 10-15 degrees about the shin's medio-lateral axis
(docs/results/learned/experiments.md, the diagnosis round), and virtual shank sensors walk
14-29 degrees from their axis depending on the data set. This measures, on virtual sensors
only, what such an error costs: the ``bandai-namco-2`` clips every shipped-style model holds
out (:func:`imuloco.methods.training.held_out_clips`) and ``--limit`` ``bandai-namco-1``
walks and backward walks, right ankle, ``phone`` noise, test seed 1000, with every clip's
sensor turned about its x axis by each angle (:func:`imuloco.methods.learned.train.inclined`),
measured as ``imuloco bench`` measures a clip (:func:`imuloco.lab.bench.measure`):
MPJPE (cm) and, on the backward walks, foot skate (cm/s). Nothing here changes a constant.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

SEED = 1000


def turned(examples: list, degrees: float) -> list:
    """``examples`` (one sensor) with the sensor turned about its x axis by ``degrees``."""
    from dataclasses import replace

    from imuloco.core.recording import Recording
    from imuloco.methods.learned.train import inclined

    out = []
    for e in examples:
        s = e.signals
        rec = Recording(np.arange(len(s)) / 30.0, s[:, None, :3], s[:, None, 3:6], ["sensor"])
        rec = inclined(rec, [degrees])
        out.append(replace(e, signals=np.concatenate([rec.acc[:, 0], rec.gyro[:, 0]], axis=1)))
    return out


def main() -> None:
    from imuloco.app.pipeline import shipped_model
    from imuloco.io.atomic import atomic_write_text, check_output
    from imuloco.io.database import load_database
    from imuloco.lab.bench import aggregate, measure
    from imuloco.methods import load_model
    from imuloco.methods.training import held_out_clips, synthesize

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=Path("../shared/data"))
    ap.add_argument("--models", required=True)
    ap.add_argument("--angles", default="-15,-8,0,8,15")
    ap.add_argument("--limit", type=int, default=12)
    ap.add_argument("-o", "--output", type=Path, default=None)
    args = ap.parse_args()
    if args.output is not None:
        check_output(args.output)
    angles = [float(a) for a in args.angles.split(",")]
    lab = held_out_clips(load_database(args.data / "bandai-namco-2", progress=False))
    other = load_database(args.data / "bandai-namco-1", progress=False)
    sets = {"lab": synthesize(lab, ["right_ankle"], "phone", SEED)}
    for content in ("walk", "walk-back"):
        keep = [i for i, c in enumerate(other.labels) if c["content"] == content][:args.limit]
        sets[content] = synthesize(other.subset(keep), ["right_ankle"], "phone", SEED)
    cols = [f"{k} {a:+.0f}°" for k in sets for a in angles]
    lines = [(f"Virtual right-ankle sensors turned about x (phone noise, seed {SEED}); lab: "
             f"{len(sets['lab'])} bandai-namco-2 validation clips; walk and walk-back: "
             f"{len(sets['walk'])} and {len(sets['walk-back'])} bandai-namco-1 clips. MPJPE cm "
             "(walk-back: MPJPE / foot skate cm/s)."), "",
             "| model | " + " | ".join(cols) + " |", "|---|" + "---:|" * len(cols)]
    for name in args.models.split(","):
        model = load_model(shipped_model("learned", "right_ankle") if name == "shipped" else name)
        cells = []
        for key, ex in sets.items():
            for a in angles:
                s = aggregate(measure(model, turned(ex, a))["clips"])
                cells.append(f"{s['mpjpe_cm']:.2f}" if key != "walk-back" else
                             f"{s['mpjpe_cm']:.2f} / {s['foot_skate_cm_s']:.0f}")
        lines.append(f"| {Path(name).name} | " + " | ".join(cells) + " |")
        print(lines[-1], flush=True)
    if args.output is not None:
        atomic_write_text(args.output, "\n".join(lines))


if __name__ == "__main__":
    main()
