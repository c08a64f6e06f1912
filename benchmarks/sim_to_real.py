"""Where a real shin phone's signals differ from the virtual sensors the models train on.

    python benchmarks/sim_to_real.py [--data ../shared/data] [-o TABLE.md] [--foot | --back]
                                     [--model FILE]

The real ``realworld-shin`` walk (without its first and last 10 s) against clean virtual
right-ankle sensors on 9 straight walks of ``bandai-namco-2`` and of ``cmu-iclone``, all
brought into the shank's anatomical frame by imuloco's own sensor-to-segment calibration and
low-passed (4th-order Butterworth, zero phase) at 3, 8 and 20 Hz. Prints a Markdown table of
the real signals' standard deviation per anatomical axis (m/s², rad/s) and the ratio real over
virtual for each motion set, then how much the virtual acceleration's spread (8 Hz band,
norm of the three axes) moves with where on the shank the sensor sits. A measurement to steer
the virtual sensors, never a fit: nothing here changes a constant.

``--foot`` measures the shoe sensors instead: 8 right-foot trials of ``real-imu/ipol-gait`` and
of ``real-imu/pyshoe-vicon``, in their makers' axes and calibrated, against clean virtual
right-foot sensors on 6 walks of ``bandai-namco-2`` (mean and standard deviation per axis,
< 8 Hz), then the share of frames the shipped foot model flags unreliable and its median
predicted error, both ways (calibrated, also inside the reference's walking bouts alone, when
it has them); and how plausible the calibrated trials' reconstructed gait is (its
cadence against the sensor-level estimator's, each foot's stance, a normal walk's about 60 %,
and the feet's skate while down).

``--back`` does the same for the lower-back sensors: 8 trials of ``real-imu/ipol-gait`` and
the 7 of ``real-imu/mobilise-d-lab``, against clean virtual L5 sensors, with the shipped
lower-back model (or ``--model FILE``, a model of that placement).
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

import numpy as np
from scipy.signal import butter, sosfiltfilt

BANDS_HZ = (3.0, 8.0, 20.0)
AXES = ("acc x (left)", "acc y (up the shin)", "acc z (forward)", "gyro x (sagittal)",
        "gyro y (long axis)", "gyro z (frontal)")
CMU_WALKS = ("002_01", "002_02", "005_01", "006_01", "007_01", "007_02", "007_03", "007_06",
             "007_07")  # trials.csv: "walk"


def spread(times: np.ndarray, acc: np.ndarray, gyro: np.ndarray, cutoff: float) -> np.ndarray:
    """Standard deviation (6,) of acc (T, 3) and gyro (T, 3) low-passed at ``cutoff`` Hz."""
    rate = 1.0 / np.median(np.diff(times))
    sos = butter(4, cutoff, fs=rate, output="sos")
    return np.r_[sosfiltfilt(sos, acc, axis=0).std(0), sosfiltfilt(sos, gyro, axis=0).std(0)]


def virtual(files: list[tuple[Path, int]], fraction: float | None = None) -> list:
    """Calibrated clean virtual right-ankle recordings (50 Hz, as the real phone) of clips
    (path, leading frames to skip), at ``fraction`` of the way from knee to ankle (default:
    the preset's)."""
    from dataclasses import replace

    from imuloco.app.pipeline import calibrated
    from imuloco.io.motionfile import read_motion
    from imuloco.sensors.placement import get_placement
    from imuloco.sensors.simulate import simulate

    place = get_placement("right_ankle")
    if fraction is not None:
        place = replace(place, fraction=fraction)
    return [calibrated(simulate(read_motion(f, skip_frames=skip), [place], rate=50.0,
                                noise="clean", seed=0))[0] for f, skip in files]


SENSOR_SETS = {"right_foot": ("ipol-gait", "pyshoe-vicon"),
               "lower_back": ("ipol-gait", "mobilise-d-lab")}


def sensor_table(data: Path, placement: str, model_file: Path | None = None) -> list[str]:
    """The ``--foot`` (``right_foot``) and ``--back`` (``lower_back``) tables (module
    docstring)."""
    from imuloco.app.pipeline import reconstruct_recording, shipped_model
    from imuloco.io.motionfile import read_motion
    from imuloco.io.realimu import read_trials
    from imuloco.methods import load_model
    from imuloco.sensors.calibration import calibrate
    from imuloco.sensors.simulate import simulate

    def stats(rec, bouts=()) -> np.ndarray:  # mean (6,) and std (6,) below 8 Hz
        rate = 1.0 / np.median(np.diff(rec.times))
        sos = butter(4, 8.0, fs=rate, output="sos")
        x = sosfiltfilt(sos, np.concatenate([rec.acc[:, 0], rec.gyro[:, 0]], 1), axis=0)
        if bouts:  # only inside the reference's walking bouts (seconds from the first sample)
            t = rec.times - rec.times[0]
            x = x[np.any([(t >= b.start) & (t <= b.end) for b in bouts], axis=0)]
        return np.r_[x.mean(0), x.std(0)]

    model = load_model(model_file or shipped_model("learned", placement))
    head = ["acc x", "acc y", "acc z", "gyro x", "gyro y", "gyro z"]
    lines = ["| source | axes | " + " | ".join(f"{a} mean" for a in head) + " | "
             + " | ".join(f"{a} std" for a in head) + " | flagged % | predicted cm |",
             "|---|---|" + "---:|" * 14]
    gait = ["", ("| source (calibrated) | cadence, reconstruction | cadence, sensor's own | "
                 "stance % L / R | foot skate cm/s |"), "|---|---:|---:|---:|---:|"]
    for name in SENSOR_SETS[placement]:
        trials = list(read_trials(data / "real-imu" / name, limit=8))
        for axes, cal in (("maker's", False), ("calibrated", True)):
            rows, flagged, predicted, plausible, walking = [], [], [], [], []
            for trial in trials:
                rec = trial.recording.select([placement])
                rows.append(stats(calibrate(rec)[0] if cal else rec))
                if cal and trial.reference.bouts:
                    walking.append(stats(calibrate(rec)[0], trial.reference.bouts))
                motion, info = reconstruct_recording(rec, model, calibrate=cal)
                flagged.append(np.mean(info["confidence"].unreliable))
                predicted.append(np.median(info["confidence"].error_m))
                if cal:
                    plausible.append(gait_check(motion, trial, placement))
            lines.append(f"| {name} ({len(trials)} trials) | {axes} | "
                         + " | ".join(f"{v:.2f}" for v in np.mean(rows, 0))
                         + f" | {100 * np.mean(flagged):.0f} | {100 * np.median(predicted):.1f} |")
        if len(walking) == len(trials):
            lines.append(f"| {name} ({len(trials)} trials) | calibrated, walking bouts only | "
                         + " | ".join(f"{v:.2f}" for v in np.mean(walking, 0)) + " | | |")
        c = np.nanmean(plausible, 0)
        gait.append(f"| {name} ({len(trials)} trials) | {c[0]:.1f} | {c[1]:.1f} | "
                    f"{c[2]:.0f} / {c[3]:.0f} | {c[4]:.1f} |")
    walks = sorted((data / "bandai-namco-2").glob("*_walk_normal_*.bvh"))[:6]
    virt = [stats(simulate(read_motion(f), [placement], rate=100.0, noise="clean", seed=0))
            for f in walks]
    lines.append(f"| virtual, bandai-namco-2 ({len(walks)} walks) | anatomical | "
                 + " | ".join(f"{v:.2f}" for v in np.mean(virt, 0)) + " | | |")
    return lines + gait


def gait_check(motion, trial, placement: str) -> list[float]:
    """Plausibility of a real trial's reconstruction (on the walker's height when known):
    its cadence, the sensor-level estimator's (:func:`imuloco.measures.sensorgait.
    sensor_gait`), each foot's stance % and the feet's skate (cm/s, as ``reconstruct``
    reports it)."""
    from imuloco.measures.gait import gait_parameters, plausibility, to_height
    from imuloco.measures.sensorgait import sensor_gait

    ref = trial.reference
    if np.isfinite(ref.height_m):
        motion = to_height(motion, ref.height_m)
    g = gait_parameters(motion)
    try:
        own = sensor_gait(trial.recording, placement, height_m=ref.height_m,
                          sensor_height_m=ref.sensor_height_m).summary()["cadence_spm"]
    except ValueError:  # a lower back without the walker's height (as bench --real)
        own = np.nan
    return [g["cadence_spm"], own, g["left_stance_pct"], g["right_stance_pct"],
            plausibility(motion)["foot_skate_cm_s"]]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=Path("../shared/data"))
    ap.add_argument("-o", "--output", type=Path, help="also write the table to this file")
    which = ap.add_mutually_exclusive_group()
    which.add_argument("--foot", action="store_true", help="the shoe sensors (module docstring)")
    which.add_argument("--back", action="store_true", help="the lower-back sensors")
    ap.add_argument("--model", type=Path, help="with --foot/--back: this model file instead of "
                    "the shipped one")
    args = ap.parse_args()
    logging.disable(logging.WARNING)  # the real log's sampling gaps are reported, not errors
    if args.foot or args.back:
        placement = "right_foot" if args.foot else "lower_back"
        return write("\n".join(sensor_table(args.data, placement, args.model)), args.output)
    from imuloco.app.pipeline import calibrated
    from imuloco.sensors.reallog import read_log

    rec, _ = read_log(args.data / "realworld-shin" / "acc_walking_shin.csv",
                      placement="right_ankle")
    rec, _ = calibrated(rec)
    keep = (rec.times > rec.times[0] + 10) & (rec.times < rec.times[-1] - 10)
    bn2 = sorted((args.data / "bandai-namco-2").glob("*_walk_normal_*.bvh"))[:6] + sorted(
        (args.data / "bandai-namco-2").glob("*_walk_active_*.bvh"))[:3]
    sets = {"bandai-namco-2": virtual([(f, 0) for f in bn2]),
            # frame 0 of every cmu-iclone file is the converter's T-pose
            "cmu-iclone": virtual([(args.data / "cmu-iclone" / f"{n}.bvh", 1)
                                   for n in CMU_WALKS])}
    lines = ["| band | source | " + " | ".join(AXES) + " |", "|---|---|" + "---:|" * len(AXES)]
    for cutoff in BANDS_HZ:
        real = spread(rec.times[keep], rec.acc[keep, 0], rec.gyro[keep, 0], cutoff)
        lines.append(f"| < {cutoff:g} Hz | real shin phone, std | "
                     + " | ".join(f"{v:.2f}" for v in real) + " |")
        for name, recs in sets.items():
            sim = np.mean([spread(r.times, r.acc[:, 0], r.gyro[:, 0], cutoff) for r in recs], 0)
            lines.append(f"| | real / {name} ({len(recs)} walks) | "
                         + " | ".join(f"{v:.2f}" for v in real / sim) + " |")
    lines += ["", "| sensor at, knee to ankle | 0.35 | 0.5 | 0.65 | 0.8 (preset) |",
              "|---|---:|---:|---:|---:|"]
    norms = [np.mean([np.linalg.norm(spread(r.times, r.acc[:, 0], r.gyro[:, 0], 8.0)[:3])
                      for r in virtual([(f, 0) for f in bn2], fraction)])
             for fraction in (0.35, 0.5, 0.65, 0.8)]
    lines.append("| acceleration spread, bandai-namco-2 walks, < 8 Hz, m/s² | "
                 + " | ".join(f"{v:.2f}" for v in norms) + " |")
    write("\n".join(lines), args.output)


def write(table: str, output: Path | None) -> None:
    """Print ``table`` and write it to ``output`` when given."""
    print(table)
    if output:
        from imuloco.io.atomic import atomic_write

        with atomic_write(output, "w") as f:
            f.write(table + "\n")


if __name__ == "__main__":
    main()
