"""Why the shipped shin model flags every frame of the real shin phone: a measurement.

    python benchmarks/shin_novelty.py [--data ../shared/data] [-o TABLE.md] [--plot CYCLES.png]
    python benchmarks/shin_novelty.py --models A.npz,B.npz [--min-still S] [-o TABLE.md]

The shipped ``learned_right_ankle.npz`` reads the real ``realworld-shin`` walk (its first two
minutes after the first 10 s, calibrated as ``reconstruct`` does) and virtual right-ankle
walks (4 clips of ``bandai-namco-2`` it trained on, ``phone`` noise), each changed by one
difference between them that issue 16's earlier rounds measured or suspected. Prints the
share of frames flagged unreliable and the median novelty (1 is typical of held-out training
motion; frames are flagged above the model's threshold, 3.5). ``--plot`` draws the six
calibrated channels over a gait cycle (mean and spread, cycles cut at mid-swing) for the real
phone and the virtual sensors of both motion sets. ``--models`` compares right-ankle model
files instead (``shipped`` for the shipped one): on the whole real walk, the share flagged,
the median novelty over the model's threshold and the gait of the reconstruction (a normal
walk: cadence equal to the signal's, about 60 % stance per foot, little foot skate); on 4
virtual walks of ``bandai-namco-1`` (styles none of them trained on), rigid and on random
straps, the share flagged. A measurement to steer the virtual sensors, never a fit: nothing
here changes a constant.
"""

from __future__ import annotations

import argparse
import itertools
import logging
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np

CHANNELS = ("acc x (left)", "acc y (up the shin)", "acc z (forward)", "gyro x (sagittal)",
            "gyro y (long axis)", "gyro z (frontal)")
CMU_WALKS = ("002_01", "002_02", "005_01", "006_01", "007_01", "007_02", "007_03")


def real_walk(data: Path, seconds: float | None = 120.0, min_still_s: float = 1.0):
    """The calibrated real shin phone's walk from 10 s in (``seconds`` long; None: to 10 s
    before its end); ``min_still_s`` as for :func:`imuloco.sensors.calibration.calibrate`."""
    from imuloco.core.recording import Recording
    from imuloco.sensors.calibration import calibrate
    from imuloco.sensors.reallog import read_log

    rec, _ = read_log(data / "realworld-shin" / "acc_walking_shin.csv", placement="right_ankle")
    rec, _ = calibrate(rec, min_still_s)
    end = rec.times[-1] - 10 if seconds is None else rec.times[0] + 10 + seconds
    k = (rec.times > rec.times[0] + 10) & (rec.times < end)
    return Recording(rec.times[k], rec.acc[k], rec.gyro[k], list(rec.placements))


def changed(rec, acc: Callable | None = None, gyro: Callable | None = None, times=None):
    """``rec`` with its acc (T, 1, 3) and gyro mapped by the functions given."""
    from imuloco.core.recording import Recording

    return Recording(rec.times if times is None else times,
                     rec.acc if acc is None else acc(rec), rec.gyro if gyro is None else gyro(rec),
                     list(rec.placements))


def dynamics(rec, k: float) -> np.ndarray:
    """The acceleration's deviation from its 2 s moving mean (gravity and tilt) times ``k``."""
    from scipy.ndimage import uniform_filter1d

    slow = uniform_filter1d(rec.acc, int(2.0 * rec.rate), axis=0, mode="nearest")
    return slow + k * (rec.acc - slow)


def novelty_rows(data: Path) -> list[str]:
    """The table (module docstring)."""
    from scipy.signal import butter, sosfiltfilt

    from imuloco.app.pipeline import shipped_model
    from imuloco.io.motionfile import read_motion
    from imuloco.methods import load_model
    from imuloco.methods.learned.train import speed_change
    from imuloco.ops.filters import resample_linear
    from imuloco.ops.rotations import from_rotvec, qrot
    from imuloco.sensors.placement import get_placement
    from imuloco.sensors.simulate import simulate

    model = load_model(shipped_model("learned", "right_ankle"))

    def score(recs) -> str:
        outs = [model.reconstruct_full(r) for r in recs]
        flagged = 100 * np.mean([np.mean(o.unreliable) for o in outs])
        return f"{flagged:.0f} | {np.median(np.concatenate([o.scores['novelty'] for o in outs])):.2f}"

    def lowpass(x: np.ndarray, hz: float, rate: float) -> np.ndarray:
        return sosfiltfilt(butter(2, hz, fs=rate, output="sos"), x, axis=0)

    walks = [read_motion(f) for f in
             sorted((data / "bandai-namco-2").glob("*_walk_normal_*.bvh"))[6:10]]
    sim = [simulate(w, ["right_ankle"], 100.0, "phone", 11) for w in walks]
    tilt = from_rotvec(np.array([np.deg2rad(13.0), 0.0, 0.0]))
    virtual = {
        "as simulated (100 Hz)": sim,
        "sampled at 50 Hz": [simulate(w, ["right_ankle"], 50.0, "phone", 11) for w in walks],
        "acceleration dynamics x 0.5": [changed(r, lambda r: dynamics(r, 0.5)) for r in sim],
        "acceleration dynamics x 0.3": [changed(r, lambda r: dynamics(r, 0.3)) for r in sim],
        "long-axis rotation x 1.5": [changed(r, gyro=lambda r: r.gyro * [1, 1.5, 1]) for r in sim],
        "acceleration low-passed at 4 Hz": [changed(r, lambda r: lowpass(r.acc, 4.0, r.rate))
                                            for r in sim],
        "tilted 13 deg about x": [changed(r, lambda r: qrot(tilt, r.acc),
                                          lambda r: qrot(tilt, r.gyro)) for r in sim],
        "walked at 0.7 of the speed": [simulate(speed_change(w, 0.7), ["right_ankle"], 100.0,
                                                "phone", 11) for w in walks],
    }
    place = get_placement("right_ankle")
    for fraction in (0.2, 0.5):
        virtual[f"sensor at {fraction} of knee to ankle (preset 0.8)"] = [
            simulate(w, [replace(place, fraction=fraction)], 100.0, "phone", 11) for w in walks]
    real = real_walk(data)
    t = real.times

    def shifted(lag: float) -> np.ndarray:
        return resample_linear(t, real.gyro[:, 0], np.clip(t + lag, t[0], t[-1]))[:, None]

    reals = {
        "as recorded": real,
        "gyroscope bias removed (its mean over the walk)": changed(
            real, gyro=lambda r: r.gyro - r.gyro.mean(0)),
        "acceleration dynamics x 1.4": changed(real, lambda r: dynamics(r, 1.4)),
        "long-axis rotation x 0.7": changed(real, gyro=lambda r: r.gyro * [1, 0.7, 1]),
        "gyroscope 0.2 s earlier": changed(real, gyro=lambda r: shifted(0.2)),
        "gyroscope 0.2 s later": changed(real, gyro=lambda r: shifted(-0.2)),
        "mirrored (a left leg)": changed(real, lambda r: r.acc * [-1, 1, 1],
                                         lambda r: r.gyro * [1, -1, -1]),
    }
    lines = ["| input | change | flagged % | median novelty |", "|---|---|---:|---:|"]
    lines += [f"| virtual, {len(walks)} bandai-namco-2 walks | {k} | {score(v)} |"
              for k, v in virtual.items()]
    lines += [f"| real shin phone, {t[-1] - t[0]:.0f} s | {k} | {score([v])} |"
              for k, v in reals.items()]
    return lines


def model_rows(data: Path, files: list[str], min_still_s: float = 1.0) -> list[str]:
    """The ``--models`` table (module docstring)."""
    from imuloco.app.pipeline import shipped_model
    from imuloco.io.motionfile import read_motion
    from imuloco.measures.gait import gait_parameters, plausibility, signal_cadence
    from imuloco.methods import load_model
    from imuloco.phases import gait_phases
    from imuloco.sensors.simulate import simulate
    from imuloco.sensors.strap import random_strap

    real = real_walk(data, None, min_still_s)
    force = real.acc[:, 0].mean(0)
    rng = np.random.default_rng(42)
    walks = [read_motion(f) for f in
             sorted((data / "bandai-namco-1").glob("*_walk_normal_*.bvh"))[:4]]
    rigid = [simulate(w, ["right_ankle"], 100.0, "phone", 7) for w in walks]
    worn = [simulate(w, ["right_ankle"], 100.0, "phone", 7, random_strap(rng)) for w in walks]
    head = (f"Real walk: {real.times[-1] - real.times[0]:.0f} s, the signal's own cadence "
            f"{signal_cadence(real):.1f} steps/min; calibrated mean inclination "
            f"{np.degrees(np.arctan2(force[2], force[1])):.1f} deg.")
    cols = ("| model | real: flagged % | novelty / threshold | cadence | stance % L / R | "
            "double support % | stride m | foot skate cm/s | virtual rigid: flagged % | "
            "virtual strapped: flagged % |")
    lines = [head, "", cols, "|---|" + "---:|" * 9]

    def flagged(model, recs) -> float:
        return 100 * float(np.mean([np.mean(model.reconstruct_full(r).unreliable)
                                    for r in recs]))

    for name in files:
        model = load_model(shipped_model("learned", "right_ankle") if name == "shipped"
                           else name)
        out = model.reconstruct_full(real)
        g = gait_parameters(out.motion, gait_phases(out.motion))

        lines.append(
            f"| {Path(name).name} | {100 * np.mean(out.unreliable):.1f} | "
            f"{np.median(out.scores['novelty']) / model.novelty_threshold_:.2f} | "
            f"{g['cadence_spm']:.1f} | {g['left_stance_pct']:.0f} / {g['right_stance_pct']:.0f} | "
            f"{g['double_support_pct']:.0f} | {g['stride_length_m']:.2f} | "
            f"{plausibility(out.motion)['foot_skate_cm_s']:.1f} | {flagged(model, rigid):.1f} | "
            f"{flagged(model, worn):.1f} |")
    return lines


def cycles(rec) -> np.ndarray:
    """The six channels of ``rec`` over each gait cycle, mid-swing to mid-swing, on 101 points
    (K, 101, 6); cycles of 0.8-1.6 s only."""
    from scipy.signal import find_peaks

    from imuloco.ops.filters import gaussian_smooth, resample_linear

    t = np.arange(rec.times[0], rec.times[-1], 0.01)
    x = resample_linear(rec.times, np.concatenate([rec.acc[:, 0], rec.gyro[:, 0]], 1), t)
    wx = gaussian_smooth(x[:, 3], 2.0)
    peaks, _ = find_peaks(-wx, height=0.5 * -np.percentile(wx, 1), distance=60)
    return np.array([resample_linear(np.linspace(0, 1, b - a), x[a:b], np.linspace(0, 1, 101))
                     for a, b in itertools.pairwise(peaks) if 80 < b - a < 160])


def plot_cycles(data: Path, path: Path) -> None:
    """The ``--plot`` figure (module docstring)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from imuloco.io.atomic import atomic_write
    from imuloco.io.motionfile import read_motion
    from imuloco.sensors.calibration import calibrate
    from imuloco.sensors.simulate import simulate

    def virtual(files, skip: int) -> np.ndarray:
        return np.concatenate([cycles(calibrate(simulate(
            read_motion(f, skip_frames=skip), ["right_ankle"], 100.0, "clean", 0))[0])
            for f in files])

    sets = [("real shin phone", cycles(real_walk(data, None)), "k"),
            ("virtual, bandai-namco-2 walks", virtual(sorted(
                (data / "bandai-namco-2").glob("*_walk_normal_*.bvh"))[:8], 0), "C0"),
            ("virtual, cmu-iclone walks", virtual(  # frame 0: the converter's T-pose
                [data / "cmu-iclone" / f"{n}.bvh" for n in CMU_WALKS], 1), "C1")]
    fig, axs = plt.subplots(2, 3, figsize=(13, 6.5), sharex=True)
    phase = np.linspace(0, 100, 101)
    for c, ax in enumerate(axs.ravel()):
        for name, x, color in sets:
            m, s = x[:, :, c].mean(0), x[:, :, c].std(0)
            ax.plot(phase, m, color, label=f"{name} ({len(x)} cycles)")
            ax.fill_between(phase, m - s, m + s, color=color, alpha=0.15)
        ax.set_title(CHANNELS[c] + (", m/s²" if c < 3 else ", rad/s"), fontsize=10)
        if c >= 3:
            ax.set_xlabel("% of the gait cycle from mid-swing")
    axs[0, 0].legend(fontsize=8)
    fig.suptitle("Shank sensor over a gait cycle, calibrated (mean ± sd): the real phone "
                 "against the virtual sensors the model learns from")
    fig.tight_layout()
    with atomic_write(path, "wb") as f:
        fig.savefig(f, format="png", dpi=80)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=Path("../shared/data"))
    ap.add_argument("-o", "--output", type=Path, help="also write the table to this file")
    ap.add_argument("--plot", type=Path, help="write the gait-cycle figure to this PNG")
    ap.add_argument("--min-still", type=float, default=1.0,
                    help="the calibration's seconds of stillness needed to use gravity at rest "
                    "(inf: always the walking-inclination prior; --models only)")
    ap.add_argument("--models", help="compare these right-ankle model files (comma-separated; "
                    "'shipped': the shipped one)")
    args = ap.parse_args()
    logging.disable(logging.WARNING)  # the real log's sampling gaps are reported, not errors
    if args.plot:
        plot_cycles(args.data, args.plot)
    table = "\n".join(model_rows(args.data, args.models.split(","), args.min_still) if args.models else
                      novelty_rows(args.data))
    print(table)
    if args.output:
        from imuloco.io.atomic import atomic_write_text

        atomic_write_text(args.output, table)


if __name__ == "__main__":
    main()
