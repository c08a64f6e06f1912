"""ipol-gait's stride and speed: the reference's definition against the walk's summary.

    python benchmarks/ipol_definition.py [--data ../shared/data/real-imu] [-o TABLE.md]

ipol-gait's reference gives each straight bout (first foot-off to the U-turn's start, the
U-turn's end to the last strike) 10 m: stride = 2 x 10 m / the strikes of both feet in it,
speed = 10 m / its duration. A foot sensor's summary reports the mean of its complete strides
and speed from its contacts' span. For every trial and foot this measures, per bout, what
separates the two: the foot's ZUPT distance over the swings that end at its contacts in the
bout (:func:`imuloco.lab.real.bout_contacts`), the first and last of those swings against
the middle ones, and the errors of both definitions against the reference (per trial, the
mean over its two bouts, as ``imuloco bench --real`` scores them). A measurement of the
protocol's definitions: nothing here changes a constant.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from imuloco.io.realimu import IPOL_BOUT_M, find_datasets, read_trials
from imuloco.lab.real import IC_TOLERANCE_S, bout_contacts
from imuloco.measures.sensorgait import sensor_gait


def bout_figures(trial) -> list[dict]:
    """One dict per foot and bout of an ipol-gait trial (see the module docstring)."""
    ref, out = trial.reference, []
    both = np.sort(np.concatenate(list(ref.initial_contacts.values())))
    for side in ("right", "left"):
        g = sensor_gait(trial.recording, f"{side}_foot")
        if not g.measured:
            continue
        for k, b in enumerate(ref.bouts):
            sel = bout_contacts(g.initial_contacts, ref.initial_contacts[side], b.start, b.end)
            sw, n = g.swings_m[sel], int(sel.sum())
            w = g.window(b.start - IC_TOLERANCE_S, b.end + IC_TOLERANCE_S).summary()
            steps = int(np.sum((both >= b.start) & (both <= b.end)))
            out.append({"trial": trial.name, "foot": side, "bout": k, "n": n, "steps": steps,
                        "time": b.end - b.start, "dist": float(sw.sum()),
                        "first": sw[0] / np.median(sw[1:-1]) if n > 2 else np.nan,
                        "last": sw[-1] / np.median(sw[1:-1]) if n > 2 else np.nan,
                        "mean_stride": w["stride_length_m"], "cadence": w["cadence_spm"],
                        "ref_stride": b.stride_length_m, "ref_speed": b.speed_mps})
    return out


def _pct(x: np.ndarray) -> np.ndarray:
    return 100.0 * (np.asarray(x, float) - 1.0)


def tables(rows: list[dict]) -> str:
    """Markdown: both definitions per trial, the bias's parts and the swings per bout."""
    lines = [("| foot | definition | figure | mean signed % | median % | mean abs % | "
              "trials within 5 % |"), "|---|---|---|---:|---:|---:|---:|"]
    parts = [("| foot | complete strides / all swings' mean | foot distance / 10 m | "
              "reference steps / 2 x foot contacts | contacts' span cadence / steps over "
              "bout time | strides' mean / reference |"), "|---|---:|---:|---:|---:|---:|"]
    swings = [("| foot | bout | first swing / middle (median) | last swing / middle "
               "(median) | foot distance m (median, quartiles) |"), "|---|---|---:|---:|---:|"]
    for side in ("right", "left"):
        r = [x for x in rows if x["foot"] == side]
        get = lambda key, rr=r: np.array([x[key] for x in rr], float)
        n, dist, time = get("n"), get("dist"), get("time")
        per_bout = {
            ("strides' mean (the walk's summary)", "stride"):
                get("mean_stride") / get("ref_stride"),
            ("strides' mean (the walk's summary)", "speed"):
                get("mean_stride") * get("cadence") / 120 / get("ref_speed"),
            ("the reference's (distance over all the bout's steps, over its time)", "stride"):
                dist / n / get("ref_stride"),
            ("the reference's (distance over all the bout's steps, over its time)", "speed"):
                dist / time / get("ref_speed")}
        trials = [x["trial"] for x in r]
        for (name, fig), ratio in per_bout.items():
            err = _pct(ratio)
            per_trial = np.array([np.mean(err[[t == u for t in trials]])
                                  for u in dict.fromkeys(trials)])
            lines.append(f"| {side} | {name} | {fig} | {per_trial.mean():+.1f} | "
                         f"{np.median(per_trial):+.1f} | {np.abs(per_trial).mean():.1f} | "
                         f"{np.mean(np.abs(per_trial) <= 5):.0%} |")
        ratios = (get("mean_stride") / (dist / n), dist / IPOL_BOUT_M, get("steps") / (2 * n),
                  get("cadence") / (120 * n / time), get("mean_stride") / get("ref_stride"))
        parts.append(f"| {side} | " + " | ".join(f"{np.nanmean(_pct(x)):+.1f}" for x in ratios)
                     + " |")
        for k in (0, 1):
            b = get("bout") == k
            q = np.percentile(dist[b], [25, 50, 75])
            swings.append(f"| {side} | {k} | {np.nanmedian(get('first')[b]):.2f} | "
                          f"{np.nanmedian(get('last')[b]):.2f} | {q[1]:.2f} ({q[0]:.2f}-"
                          f"{q[2]:.2f}) |")
    return "\n\n".join("\n".join(t) for t in (lines, parts, swings))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default="../shared/data/real-imu")
    ap.add_argument("-o", "--out", type=Path)
    args = ap.parse_args()
    rows = []
    for layout, path in find_datasets(args.data):
        if layout == "ipol-gait":
            for trial in read_trials(path, layout, None):
                rows += bout_figures(trial)
    text = tables(rows)
    print(text)
    if args.out:
        from imuloco.io.atomic import atomic_write_text

        atomic_write_text(args.out, text)


if __name__ == "__main__":
    main()
