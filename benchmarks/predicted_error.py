"""A model file's predicted error against its actual error (issue 16's confidence).

    python benchmarks/predicted_error.py --models shipped,A.npz,... [--data ../shared/data]
        [--placement right_ankle] [-o TABLE.md]

For each model file (``shipped``: the placement's shipped model), one sensor at
``--placement`` (the right ankle), ``phone`` noise, test seed 1000, measured as ``imuloco
bench`` measures a clip (:func:`imuloco.lab.bench.measure`): the rms over frames of the
actual error (rms over joints a frame), of the predicted error (``error_m``, calibrated when
the file holds a calibration) and of the network's own estimate (``sigma_m``), in cm, on the
``bandai-namco-2`` clips every shipped-style model holds out
(:func:`imuloco.methods.training.held_out_clips`) and on ``bandai-namco-1`` (per content
too). Models trained on ``bandai-namco-1`` are in-sample there.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

SEED = 1000


def rms_cm(rows: list[dict], key: str, content: str | None = None) -> float:
    v = np.concatenate([r[key] if content is None else r[key][r["content"] == content]
                        for r in rows])
    return float(100 * np.sqrt(np.mean(np.square(v))))


def main() -> None:
    from imuloco.app.pipeline import shipped_model
    from imuloco.io.atomic import atomic_write_text, check_output
    from imuloco.io.database import load_database
    from imuloco.lab.bench import measure
    from imuloco.methods import load_model
    from imuloco.methods.training import held_out_clips, synthesize

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=Path("../shared/data"))
    ap.add_argument("--models", required=True)
    ap.add_argument("--placement", default="right_ankle")
    ap.add_argument("-o", "--output", type=Path, default=None)
    args = ap.parse_args()
    if args.output is not None:
        check_output(args.output)
    lab = held_out_clips(load_database(args.data / "bandai-namco-2", progress=False))
    other = load_database(args.data / "bandai-namco-1", progress=False)
    sets = {"lab": synthesize(lab, [args.placement], "phone", SEED),
            "bandai-namco-1": synthesize(other, [args.placement], "phone", SEED)}
    contents = sorted({c["content"] for c in other.labels})
    cols = ["lab", "bandai-namco-1", *contents]
    lines = [(f"Actual / predicted / network's own estimate, rms over frames, cm "
              f"({args.placement.replace('_', ' ')}, "
             f"phone noise, seed {SEED}; lab: {len(lab)} held-out bandai-namco-2 clips; "
             f"bandai-namco-1: {len(other)} clips)."), "",
             "| model | " + " | ".join(cols) + " |", "|---|" + "---|" * len(cols)]
    for name in args.models.split(","):
        model = load_model(shipped_model("learned", args.placement) if name == "shipped"
                           else name)
        rows = {k: measure(model, ex)["confidence"] for k, ex in sets.items()}
        cells = [(rows[c], None) for c in ("lab", "bandai-namco-1")]
        cells += [(rows["bandai-namco-1"], c) for c in contents]
        lines.append(f"| {Path(name).name} | " + " | ".join(
            " / ".join(f"{rms_cm(r, k, c):.2f}" for k in ("actual_m", "error_m", "score_sigma_m"))
            for r, c in cells) + " |")
        print(lines[-1], flush=True)
    if args.output is not None:
        atomic_write_text(args.output, "\n".join(lines))


if __name__ == "__main__":
    main()
