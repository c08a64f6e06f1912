"""Peak memory and time of `imuloco render` on a 10-minute reconstructed walk.

    python benchmarks/render_memory.py [--bvh WALK.bvh [--report WALK.json]] [--work DIR]
                                       [--cases mp4,gif,out,window] [--src SRC]

Without ``--bvh`` the walk is the real ``../shared/data/realworld-shin`` recording (640 s of a
phone on the shin) reconstructed by ``imuloco reconstruct`` with the shipped model, into
``--work DIR`` (default: a temporary folder; kept and reused when given). Each case then runs
``imuloco render`` in a fresh child process:

- ``mp4``: ``-o walk.mp4`` (the whole walk, every frame);
- ``gif``: ``-o walk.gif`` (cut at 30 s, 15 fps, with a message);
- ``out``: ``--out DIR`` (MP4, GIF and HTML viewer at once: what took 14 GB before);
- ``window``: ``--start 300 --end 330 -o window.mp4``.

Printed per case: the peak resident memory of the largest process (``ru_maxrss`` of the
child's tree: Python or its ffmpeg), the peak of the whole tree's sum (sampled every 50 ms with
psutil), wall and CPU seconds (user + system of the tree), the frames written and the load
average when it started (2 cores shared with other jobs: times vary with it). ``--src`` runs
another source tree (``PYTHONPATH``), e.g. ``/work/main/src`` to compare before and after.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import tempfile
import threading
import time
from pathlib import Path

import psutil

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "realworld-shin"
CASES = {
    "mp4": ["-o", "{work}/walk.mp4"],
    "gif": ["-o", "{work}/walk.gif"],
    "out": ["--out", "{work}/out"],
    "window": ["--start", "300", "--end", "330", "-o", "{work}/window.mp4"],
}


def reconstruct(work: Path) -> tuple[Path, Path]:
    """The real shin walk reconstructed by the shipped model (reused when already there)."""
    bvh, report = work / "walk.bvh", work / "walk.json"
    if not (bvh.exists() and report.exists()):
        if not DATA.is_dir():
            raise SystemExit(f"{DATA} is absent: give --bvh")
        subprocess.run(["imuloco", "reconstruct", str(DATA / "acc_walking_shin.csv"),
                        "--placement", "right_ankle", "-o", str(bvh), "--report", str(report),
                        "--force"], check=True, stdout=subprocess.DEVNULL)
    return bvh, report


def tree_rss(proc: psutil.Process) -> int:
    """Resident bytes of ``proc`` and its descendants now."""
    total = 0
    for p in [proc, *proc.children(recursive=True)]:
        try:
            total += p.memory_info().rss
        except psutil.Error:  # ended between the listing and the reading
            pass
    return total


def measure(cmd: list[str], env: dict[str, str]) -> dict:
    """Run ``cmd``; its peaks, times and exit code."""
    load = os.getloadavg()[0]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    child = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True)
    peak, done = [0], threading.Event()

    def sample() -> None:
        proc = psutil.Process(child.pid)
        while not done.is_set():
            try:
                peak[0] = max(peak[0], tree_rss(proc))
            except psutil.Error:
                return
            done.wait(0.05)

    sampler = threading.Thread(target=sample)
    sampler.start()
    _, err = child.communicate()
    wall = time.perf_counter() - t0
    done.set()
    sampler.join()
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if child.returncode:
        raise SystemExit(f"{' '.join(cmd)} failed ({child.returncode}): {err[-2000:]}")
    return {"peak_process_mb": round(after.ru_maxrss / 1024),  # the largest one ever reaped
            "peak_tree_mb": round(peak[0] / 2**20), "wall_s": round(wall, 1),
            "cpu_s": round(after.ru_utime + after.ru_stime - before.ru_utime
                           - before.ru_stime, 1),
            "load_at_start": round(load, 1), "said": [line for line in err.splitlines()
                                                      if "GIF" in line or "Error" in line]}


def frames(path: Path) -> int:
    """Frames in an MP4 (counted by ffmpeg) or a GIF (by Pillow)."""
    import imageio_ffmpeg
    from PIL import Image

    if path.suffix == ".mp4":
        return imageio_ffmpeg.count_frames_and_secs(str(path))[0]
    with Image.open(path) as gif:
        return gif.n_frames


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--bvh", type=Path, default=None)
    ap.add_argument("--report", type=Path, default=None)
    ap.add_argument("--work", type=Path, default=None)
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--src", type=Path, default=None, help="PYTHONPATH of the tree to run")
    args = ap.parse_args()
    work = args.work or Path(tempfile.mkdtemp(prefix="imuloco-render-"))
    work.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ)
    if args.src is not None:
        env["PYTHONPATH"] = str(args.src)
    if args.bvh is None:
        bvh, report = reconstruct(work)
    else:
        bvh, report = args.bvh, args.report
    for case in args.cases.split(","):
        cmd = ["imuloco", "render", str(bvh), *(["--report", str(report)] if report else []),
               *[a.format(work=work) for a in CASES[case]], "--force"]
        result = {"case": case, **measure(cmd, env)}
        written = [Path(a.format(work=work)) for a in CASES[case] if "{work}" in a]
        if case == "out":
            written = sorted(written[0].glob("*.mp4")) + sorted(written[0].glob("*.gif"))
        result["frames"] = {p.name: frames(p) for p in written}
        print(json.dumps(result), flush=True)


if __name__ == "__main__":
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    main()
