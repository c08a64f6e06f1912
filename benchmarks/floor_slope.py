"""Foot contacts from a level floor against a floor that may slope: a measurement.

    python benchmarks/floor_slope.py [--data ../shared/data] [--limit N] [-o TABLE.md]

For each motion set and content of ``../shared/data`` (``cmu-iclone``: every clip;
``bandai-namco-1`` and ``bandai-namco-2``: at most ``--limit`` clips a content, evenly spread),
labels the ground truth's foot contacts twice with :func:`imuloco.phases.foot_contacts`: from
one floor level per clip (``sloped_floor=False``, the rule before the sloping floors of
``cmu-iclone`` were found) and from the floor the clip has (the default,
:func:`imuloco.phases.contacts.floor_under`). Prints per group the mean stance share per foot
(either heel or toe down), the largest change of a clip's stance share, the mean rise of the
fitted floor under the heels over the clip and the ground truth's own foot skate
(:func:`imuloco.measures.metrics.foot_skate` of the ground truth against itself) under each
labelling. A measurement, never a fit: nothing here changes a constant.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

import numpy as np

from imuloco.io.database import load_database
from imuloco.measures.metrics import foot_skate
from imuloco.phases.contacts import FEET, SPEED_TOL, floor_under, foot_contacts

SETS = ("cmu-iclone", "bandai-namco-2", "bandai-namco-1")


def floor_rise(motion) -> float:
    """Centimetres between the fitted floor's lowest and highest point under the heels."""
    pos = motion.part_positions([f"{s}_ankle" for s in FEET])
    leg = motion.skeleton.leg_length()
    speed = np.linalg.norm(np.gradient(pos, axis=0), axis=-1) * motion.fps
    return 100 * float(np.ptp(floor_under(pos, speed < SPEED_TOL * leg, leg)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default="../shared/data")
    ap.add_argument("--limit", type=int, default=20, help="clips a content (Bandai-Namco)")
    ap.add_argument("-o", "--output", help="also write the table to this Markdown file")
    args = ap.parse_args()
    logging.disable(logging.WARNING)
    lines = [("| set | content | clips | stance L/R level % | stance L/R sloped % | "
              "max clip change (pts) | floor rise (cm) | GT skate level / sloped (cm/s) |"),
             "|---|---|---|---|---|---|---|---|"]
    for name in SETS:
        folder = Path(args.data) / name
        full = load_database(folder, progress=False)
        for content in sorted({lab["content"] for lab in full.labels}):
            db = load_database(folder, content=[content], progress=False,
                               limit=None if name == "cmu-iclone" else args.limit)
            rows = []
            for m in db.clips:
                before = foot_contacts(m, sloped_floor=False)
                after = foot_contacts(m)
                rows.append([100 * before["left_foot"].mean(), 100 * before["right_foot"].mean(),
                             100 * after["left_foot"].mean(), 100 * after["right_foot"].mean(),
                             floor_rise(m), foot_skate(m, m, before), foot_skate(m, m, after)])
            r = np.array(rows)
            change = np.abs(r[:, 2:4] - r[:, 0:2]).max()
            lines.append(f"| {name} | {content} | {len(r)} | {r[:, 0].mean():.0f} / "
                         f"{r[:, 1].mean():.0f} | {r[:, 2].mean():.0f} / {r[:, 3].mean():.0f} | "
                         f"{change:.1f} | {r[:, 4].mean():.1f} | {np.nanmean(r[:, 5]):.2f} / "
                         f"{np.nanmean(r[:, 6]):.2f} |")
            print(lines[-1], flush=True)
    if args.output:
        from imuloco.io.atomic import atomic_write_text

        atomic_write_text(args.output, "\n".join(lines))


if __name__ == "__main__":
    main()
