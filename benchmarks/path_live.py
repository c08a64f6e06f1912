"""The live avatar's path against the offline one (issue 40, live mode), and the live delay.

    python benchmarks/path_live.py [--placements right_ankle,right_foot,lower_back]
        [--real-shin SECONDS] [--no-delay]

Each recording is streamed sample by sample through :class:`imuloco.app.live.session.
LiveSession` (the shipped model of the placement, calibration on its first 4 s, the path's
estimate inline: deterministic) and reconstructed offline from the same samples
(:func:`imuloco.paths.follow.follow_recording`, the frames the session feeds its model).
Printed per recording: the distance walked (metres, :func:`imuloco.paths.metrics.
walked_distance` of each root's floor path) by the model's own root, the live root, the
offline path and the offline animation; the live one against the offline path (per cent);
the largest step of the live root in one frame and of the offline animation's root (cm);
the strides the live session confirmed and how long after their end footfall (stream s).

Recordings: the bundled sample's walk_normal_001 simulated (phone noise, seed 3) on each
placement (9 s); with ``--real-shin``, that many seconds of the real ``realworld-shin``
walk (``../shared``). The delay: per frame, the stream seconds from the frame's time to the
sample that completed it (``trigger - time``), and the wall time of each :meth:`push` that
returned a frame (its thread's CPU time, p50/p99 ms: the machine is shared), with the path
followed (its estimate inline, as here) and without.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from imuloco.app.live.session import LiveSession, offline_frames
from imuloco.app.pipeline import choose_model
from imuloco.core.recording import Recording
from imuloco.io.database import load_sample
from imuloco.paths.base import BodyPath
from imuloco.paths.follow import follow_recording
from imuloco.paths.metrics import walked_distance
from imuloco.sensors.simulate import simulate

CALIB_S = 4.0


def real_shin(seconds: float) -> Recording:
    from imuloco.sensors.reallog import read_log

    data = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"
    rec, _ = read_log(data / "realworld-shin" / "acc_walking_shin.csv", placement="right_ankle")
    k = (rec.times > rec.times[0] + 10) & (rec.times < rec.times[0] + 10 + seconds)
    return Recording(rec.times[k], rec.acc[k], rec.gyro[k], list(rec.placements))


def stream(method, rec: Recording, follow: bool) -> tuple[list, LiveSession, list[float]]:
    s = LiveSession(method, CALIB_S, follow_path=follow)
    frames, wall = [], []
    for i in range(len(rec.times)):
        t = time.thread_time()
        out = s.push(rec.times[i], rec.acc[i], rec.gyro[i])
        if out and s.calibration is not None and len(out) < 5:  # not the calibration's burst
            wall.append(time.thread_time() - t)
        frames += out
    return frames, s, wall


def floor_distance(root: np.ndarray, fps: float) -> float:
    xy = root[:, [2, 0]]
    return walked_distance(BodyPath(np.arange(len(xy)) / fps, xy, None, [], [], "", ""))


def run(name: str, placement: str, rec: Recording, delay: bool) -> None:
    method = choose_model(placement=placement).method
    frames, s, wall_on = stream(method, rec, True)
    fps = float(method.fps_)
    live = np.stack([f.root for f in frames])
    signals = offline_frames(rec.times, rec.acc, rec.gyro, fps, s.calibration.rotations)
    own = method.reconstruct_signals(signals)
    followed, report = follow_recording(own, rec, placement)  # as reconstruct does
    steps_live = np.linalg.norm(np.diff(live[:, [0, 2]], axis=0), axis=1)
    steps_off = np.linalg.norm(np.diff(followed.root[:, [0, 2]], axis=0), axis=1)
    d_own = floor_distance(own.root, fps)
    d_live = floor_distance(live, fps)
    d_path = report["distance_m"] if report else float("nan")
    d_anim = floor_distance(followed.root, fps)
    print(f"{name:28s} {placement:12s} own {d_own:6.2f} m  live {d_live:6.2f} m  offline path "
          f"{d_path:6.2f} m  offline animation {d_anim:6.2f} m  live/path "
          f"{100 * (d_live / d_path - 1):+5.1f} %  live/animation {100 * (d_live / d_anim - 1):+5.1f}"
          f" %  max step live {100 * steps_live.max():.1f} cm, offline {100 * steps_off.max():.1f}"
          f" cm, own {100 * np.linalg.norm(np.diff(own.root[:, [0, 2]], axis=0), axis=1).max():.1f}"
          f" cm  strides read {s.strides.runs if s.strides else 0} runs")
    if delay:
        _, _, wall_off = stream(method, rec, False)
        lag = np.array([f.trigger - f.time for f in frames
                        if f.time > rec.times[0] + s.calibration.seconds])
        print(f"  delay: trigger - time {1000 * np.median(lag):.1f} ms median (max "
              f"{1000 * lag.max():.1f}); push CPU p50/p99 ms: followed "
              f"{1000 * np.percentile(wall_on, 50):.2f}/{1000 * np.percentile(wall_on, 99):.2f},"
              f" not {1000 * np.percentile(wall_off, 50):.2f}/"
              f"{1000 * np.percentile(wall_off, 99):.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--placements", default="right_ankle,right_foot,lower_back")
    ap.add_argument("--real-shin", type=float, default=None)
    ap.add_argument("--no-delay", action="store_true")
    args = ap.parse_args()
    clip = next(c for c in load_sample().clips if c.name == "dataset-2_walk_normal_001")
    for p in args.placements.split(","):
        run(clip.name, p, simulate(clip, [p], 100.0, "phone", 3), not args.no_delay)
    if args.real_shin:
        run(f"realworld-shin {args.real_shin:g} s", "right_ankle", real_shin(args.real_shin),
            not args.no_delay)


if __name__ == "__main__":
    main()
