"""The foot sensor's steps on simulated shoe IMUs, against the motion's own foot strikes.

    python benchmarks/foot_steps.py [--data ../shared/data] [--limit 12] [--noise imu]
                                    [-o TABLE.md]

Virtual right- and left-foot sensors (``simulate``, 100 Hz, the ``imu`` noise preset by
default) on the clips of ``bandai-namco-2`` and ``bandai-namco-1`` (at most ``--limit`` per
content, evenly spread), measured by :func:`imuloco.measures.sensorgait.foot_gait` as a real
shoe sensor is. The truth is each foot's strikes by the motion's own contacts
(:func:`imuloco.phases.gait_phases`); strikes less than 0.5 s from the clip's start or 0.2 s
from its end (no whole swing before them or stance after) are left out. Per content: the
clips (feet), the mean absolute step count error (%, over the strikes' span widened by the
matching tolerance), the matched, missed and extra contacts (one to one within 0.25 s,
:func:`imuloco.lab.real.match_events`) and the matched ones' timing error (median of
the absolute and of the signed, ms; negative: early). A check beside the real recordings;
nothing is fitted to it.
"""

from __future__ import annotations

import argparse
import logging
from collections import defaultdict
from pathlib import Path

import numpy as np

CONTENTS = ("walk", "walk-turn-left", "walk-turn-right", "run", "dash", "walk-back", "walk-left",
            "walk-right")
EDGE_S = (0.5, 0.2)  # a running swing's length before a strike, a short stance after it


def measure(data: Path, limit: int, noise: str, progress: bool = True) -> dict[str, dict]:
    """Per content: ``clips``, ``steps_err_pct``, ``matched``, ``missed``, ``extra``,
    ``ic_median_ms``, ``ic_bias_ms``."""
    from tqdm.auto import tqdm

    from imuloco.io.database import load_database
    from imuloco.lab.real import IC_TOLERANCE_S, match_events
    from imuloco.measures.sensorgait import foot_gait
    from imuloco.phases import gait_phases
    from imuloco.sensors.simulate import simulate

    clips = []
    for name in ("bandai-namco-2", "bandai-namco-1"):
        for content in CONTENTS:
            db = load_database(data / name, content=[content], limit=limit, progress=False)
            clips += [(content, c) for c in db.clips]
    out: dict[str, dict] = defaultdict(lambda: {"clips": 0, "err": [], "dt": [],
                                                "matched": 0, "missed": 0, "extra": 0})
    for seed, (content, clip) in enumerate(tqdm(clips, desc="clips", disable=not progress)):
        rec = simulate(clip, ["right_foot", "left_foot"], rate=100.0, noise=noise, seed=seed)
        steps = gait_phases(clip).steps
        for k, foot in enumerate(("right", "left")):
            truth = np.asarray(steps[foot], float) / clip.fps
            # a contact is measurable when its swing and the stance after it are in the clip
            truth = truth[(truth >= EDGE_S[0]) & (truth <= rec.times[-1] - EDGE_S[1])]
            if len(truth) < 2:
                continue
            g = foot_gait(rec.times, rec.acc[:, k], rec.gyro[:, k], foot)
            est = g.initial_contacts if g.measured else np.zeros(0)
            est = est[(est >= truth[0] - IC_TOLERANCE_S) & (est <= truth[-1] + IC_TOLERANCE_S)]
            errs, missed, extra = match_events(truth, est)
            row = out[content]
            row["clips"] += 1
            row["err"].append(100.0 * abs(len(est) - len(truth)) / len(truth))
            row["dt"] += list(errs)
            row["matched"] += len(errs)
            row["missed"] += missed
            row["extra"] += extra
    return {c: {**r, "steps_err_pct": float(np.mean(r.pop("err"))),
                "ic_median_ms": 1e3 * float(np.median(np.abs(r["dt"]))),
                "ic_bias_ms": 1e3 * float(np.median(r.pop("dt")))} for c, r in out.items()}


def table(rows: dict[str, dict]) -> str:
    lines = ["| content | feet | steps % | matched | missed | extra | IC ms | IC bias ms |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for c in [c for c in CONTENTS if c in rows]:
        r = rows[c]
        lines.append(f"| {c} | {r['clips']} | {r['steps_err_pct']:.1f} | {r['matched']} | "
                     f"{r['missed']} | {r['extra']} | {r['ic_median_ms']:.0f} | "
                     f"{r['ic_bias_ms']:.0f} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=Path("../shared/data"))
    ap.add_argument("--limit", type=int, default=12)
    ap.add_argument("--noise", default="imu")
    ap.add_argument("-o", "--out", type=Path)
    a = ap.parse_args()
    logging.basicConfig(level=logging.WARNING)
    text = table(measure(a.data, a.limit, a.noise))
    print(text)
    if a.out:
        from imuloco.io.atomic import atomic_write_text

        atomic_write_text(a.out, text + "\n")


if __name__ == "__main__":
    main()
