"""Standing is standing on real recordings (issue 41): the shipped models with and without the
per-part fallback over the standing parts of real recordings. ipol-gait trials (stand, walk
10 m, turn, walk back, stop; a foot IMU: the ``right_foot`` model) stand before their
``TrialBoundaries`` and after; the RealWorld shin recording stands for its first 4 s (its raw
gyro's spread stays under 0.03 rad/s until 4 s, then the walk starts). Per
recording: steps the reconstruction's legs take while standing (the reference: none), the
ankles' horizontal speed there (cm/s; a planted foot: 0), and the steps over the whole trial
against the reference's.

    nice -n 10 python benchmarks/standing_real.py [--trials 12]
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from imuloco.app.pipeline import choose_model, reconstruct_recording
from imuloco.core.recording import Recording
from imuloco.io.realimu import read_trials
from imuloco.phases import gait_phases
from imuloco.sensors.reallog import read_log

D = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def standing_numbers(motion, t0: float, windows: list[tuple[float, float]]) -> dict:
    """Steps (strikes of either foot) and mean ankle horizontal speed (cm/s) inside
    ``windows`` (seconds on the recording's clock, whose first frame is ``t0``), and all
    steps."""
    ph = gait_phases(motion)
    t = t0 + np.arange(motion.num_frames) / motion.fps
    strikes = t[np.concatenate([ph.steps["left"], ph.steps["right"]]).astype(int)]
    inside = np.zeros(motion.num_frames, bool)
    for a, b in windows:
        inside |= (t >= a) & (t < b)
    feet = motion.part_positions(["left_ankle", "right_ankle"])[..., [0, 2]]
    speed = np.linalg.norm(np.diff(feet, axis=0), axis=-1).mean(axis=1) * motion.fps * 100
    return {"steps_standing": int(sum(((strikes >= a) & (strikes < b)).sum()
                                      for a, b in windows)),
            "ankle_cm_s": float(speed[inside[1:]].mean()), "steps": len(strikes),
            "standing_s": float(sum(b - a for a, b in windows))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", type=int, default=12)
    args = ap.parse_args()
    rows = []
    foot = choose_model(placement="right_foot").method if args.trials else None
    trials = read_trials(D / "real-imu" / "ipol-gait", limit=args.trials) if args.trials else []
    for trial in trials:
        rec = trial.recording.select(["right_foot"])
        a, b = trial.reference.bouts[0].start, trial.reference.bouts[-1].end
        windows = [(rec.times[0], a), (b, rec.times[-1])]
        ref_steps = sum(len(v) for v in trial.reference.initial_contacts.values())
        for on in (False, True):
            motion, _ = reconstruct_recording(Recording(rec.times, rec.acc, rec.gyro,
                                                        ["right_foot"]), foot, fallback=on)
            rows.append({"name": trial.name, "fallback": on, "ref_steps": ref_steps,
                         **standing_numbers(motion, rec.times[0], windows)})
            print(rows[-1], flush=True)
    shin = choose_model(placement="right_ankle").method
    rec, _ = read_log(D / "realworld-shin" / "acc_walking_shin.csv", placement="right_ankle")
    keep = rec.times < rec.times[0] + 60.0  # the standing start and the first walk
    rec = Recording(rec.times[keep], rec.acc[keep], rec.gyro[keep], rec.placements)
    for on in (False, True):
        motion, _ = reconstruct_recording(rec, shin, fallback=on)
        rows.append({"name": "realworld-shin (first 4 s)", "fallback": on, "ref_steps": None,
                     **standing_numbers(motion, rec.times[0],
                                        [(rec.times[0], rec.times[0] + 4.0)])})
        print(rows[-1], flush=True)
    for on in (False, True):
        sel = [r for r in rows if r["fallback"] == on and r["ref_steps"] is not None]
        if not sel:
            continue
        print(f"ipol-gait, fallback {'on' if on else 'off'}: {len(sel)} trials, "
              f"{sum(r['standing_s'] for r in sel):.0f} s standing, steps while standing "
              f"{sum(r['steps_standing'] for r in sel)}, ankle speed there "
              f"{np.mean([r['ankle_cm_s'] for r in sel]):.2f} cm/s, steps "
              f"{sum(r['steps'] for r in sel)} (reference {sum(r['ref_steps'] for r in sel)})")


if __name__ == "__main__":
    main()
