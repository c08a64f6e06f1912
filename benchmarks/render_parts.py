"""Where a rendered frame's CPU goes: drawing (Python, Agg) and encoding (ffmpeg) apart.

    python benchmarks/render_parts.py WALK.bvh [--report WALK.json] [--start 100] [--frames 900]

Draws ``--frames`` frames of the walk from ``--start`` seconds with the renderer ``imuloco
render`` uses (the predicted-error strip when ``--report`` is given), timing the drawing alone
(CPU seconds of this process per frame); then sends the same frames (RGBA, as ``render`` does)
to ffmpeg for each x264 setting below, timing ffmpeg's CPU per frame (its YUV conversion
included) and giving the file's size and its mean absolute difference to the drawn frames
(0-255). ``current`` is :class:`imuloco.viz.skeleton.VideoWriter`'s own; the others are
what was tried. The frames are held in memory (900 frames: 440 MB).
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import tempfile
import time
from pathlib import Path

import imageio_ffmpeg
import numpy as np

from imuloco.app.confidence import Confidence
from imuloco.io.motionfile import read_motion
from imuloco.viz.skeleton import StickRenderer, VideoWriter

X264 = {
    "medium CRF 15 (before)": ["-preset", "medium", "-crf", "15"],
    "superfast CRF 23": ["-preset", "superfast", "-crf", "23"],
    "ultrafast CRF 23": ["-preset", "ultrafast", "-crf", "23"],
}


def children_cpu() -> float:
    """CPU seconds (user + system) of the children reaped so far."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def encode(frames: np.ndarray, path: Path, fps: float, params: list[str] | None) -> float:
    """ffmpeg's CPU seconds per frame encoding ``frames`` (N, H, W, 4) into ``path`` with x264
    ``params`` (None: :class:`VideoWriter`'s own)."""
    before = children_cpu()
    if params is None:
        with VideoWriter(path, (frames.shape[2], frames.shape[1]), fps, overwrite=True,
                         channels=4) as out:
            for f in frames:
                out.send(f)
    else:
        h, w = frames.shape[1:3]
        subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-loglevel", "error", "-f",
                        "rawvideo", "-pix_fmt", "rgba", "-s", f"{w}x{h}", "-r", f"{fps}", "-i",
                        "-", "-c:v", "libx264", "-pix_fmt", "yuv420p", *params, str(path)],
                       input=frames.tobytes(), check=True)
    return (children_cpu() - before) / len(frames)


def difference(path: Path, frames: np.ndarray) -> float:
    """Mean absolute difference (0-255) of every 30th decoded frame to the drawn one."""
    reader = imageio_ffmpeg.read_frames(str(path), pix_fmt="rgb24")
    next(reader)  # the metadata
    h, w = frames.shape[1:3]
    return float(np.mean([np.abs(np.frombuffer(b, np.uint8).reshape(h, w, 3).astype(int)
                                 - frames[i, ..., :3]).mean()
                          for i, b in enumerate(reader) if i % 30 == 0]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("bvh", type=Path)
    ap.add_argument("--report", type=Path, default=None)
    ap.add_argument("--start", type=float, default=100.0)
    ap.add_argument("--frames", type=int, default=900)
    args = ap.parse_args()
    motion = read_motion(args.bvh)
    conf = (Confidence.from_report(args.report, motion.num_frames, motion.fps)
            if args.report else None)
    renderer = StickRenderer([motion], [motion.name],
                             error_m=[conf.error_m if conf else None],
                             unreliable=[conf.unreliable if conf else None])
    first = round(args.start * motion.fps)
    frames = np.empty((args.frames, renderer.size[1], renderer.size[0], 4), np.uint8)
    t0 = time.process_time()
    for i in range(args.frames):
        frames[i] = renderer.draw(first + i)
    draw = (time.process_time() - t0) / args.frames
    print(json.dumps({"part": "drawing", "cpu_ms_per_frame": round(1e3 * draw, 2),
                      "frame": list(renderer.size)}), flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        for name, params in {"current": None, **X264}.items():
            path = Path(tmp) / "x.mp4"
            cpu = encode(frames, path, motion.fps, params)
            print(json.dumps({"part": f"ffmpeg x264 {name}",
                              "cpu_ms_per_frame": round(1e3 * cpu, 2),
                              "kb_per_10_s": round(path.stat().st_size / 1e3 * 10 * motion.fps
                                                   / args.frames),
                              "mean_abs_diff": round(difference(path, frames), 2)}),
                  flush=True)


if __name__ == "__main__":
    main()
