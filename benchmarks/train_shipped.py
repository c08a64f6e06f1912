"""Train every shipped ``learned`` weight file from the shared motion and time it (issue 16:
all shipped weights within 60 minutes on a 2-core CPU).

Runs the recipes of ``src/imuloco/data/models/README.md`` as ``imuloco`` commands, ``--jobs``
trainings at a time (one thread each): the shin ensemble's four runs, the foot model, the
lower-back model and the shin + watch pair's two runs, then the ensembles, their mirrors and
the shin's two calibrations. Prints each step's wall time, CPU time (the process and its
threads, from ``os.wait4``) and peak memory, the machine's load while it ran, and how far each
file's weights lie from the shipped file's.

    python benchmarks/train_shipped.py --shared ../shared/data --out train-shipped
    python benchmarks/train_shipped.py --dry-run   # print the commands only
"""

from __future__ import annotations

import argparse
import os
import shlex
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "src" / "imuloco" / "data" / "models"
MOTION = ("bandai-namco-2", "bandai-namco-1", "cmu-iclone")
SHIN_SEEDS = (0, 1, 2, 3)
# the phone on the shin and the watch on the left wrist (issue 46): two runs on all motion and
# the everyday actions, the shin recipe otherwise
ACTIONS = ("bandai-namco-1-actions", "bandai-namco-2-actions")
PAIR = "right_ankle,left_wrist"
PAIR_SEEDS = (0, 1)
# the calibration the shin ensemble ships with: fitted on the out-of-fold results of two
# draws of 3-network ensembles (sigma, novelty and the members' spread; fourteenth round)
CALIBRATION_RESULTS = ROOT / "docs" / "results" / "generalization" / "ensemble-spread"


@dataclass
class Step:
    """One command, its log and what it cost."""

    name: str
    args: list[str]
    wall_s: float = float("nan")
    cpu_s: float = float("nan")
    peak_gb: float = float("nan")


def imuloco() -> list[str]:
    """The ``imuloco`` command of this interpreter's environment."""
    script = Path(sys.executable).with_name("imuloco")
    return [str(script)] if script.exists() else [sys.executable, "-c",
                                                   "from imuloco.cli import main; main()"]


def trainings(shared: Path, out: Path) -> list[Step]:
    """The independent trainings, longest first (the models README's recipes)."""
    data = ",".join(str(shared / m) for m in MOTION)
    common = ["train", "--method", "learned", "--data", data, "--noise", "phone",
              "--param", "threads=1", "--force"]
    steps = [Step(f"shin seed {s}", common + [
        "--placement", "right_ankle", "--param", "epochs=5", "--param", "strap=0.5",
        "--param", "incline=15", "--param", f"seed={s}", "-o", str(out / f"shin{s}.npz")])
        for s in SHIN_SEEDS]
    steps.append(Step("foot", common + [
        "--placement", "right_foot", "--param", "epochs=6", "-o",
        str(out / "learned_right_foot.npz"), "--mirrored", str(out / "learned_left_foot.npz")]))
    steps.append(Step("lower back", common + [
        "--placement", "lower_back", "--param", "epochs=6", "-o",
        str(out / "learned_lower_back.npz")]))
    pair = ["--data", ",".join(str(shared / m) for m in MOTION + ACTIONS), *common[5:]]  # the common flags after --data
    steps += [Step(f"shin+watch seed {s}", ["train", "--method", "learned", *pair,
                   "--placement", PAIR, "--param", "epochs=5", "--param", "strap=0.5",
                   "--param", "incline=15", "--param", f"seed={s}", "-o",
                   str(out / f"pair{s}.npz")]) for s in PAIR_SEEDS]
    return steps


def pair_finish(shared: Path, out: Path) -> list[Step]:
    """The shin + watch ensemble and its mirror, after its runs."""
    return [Step("shin+watch ensemble + mirror", [
        "ensemble", *(str(out / f"pair{s}.npz") for s in PAIR_SEEDS), "--data",
        str(shared / MOTION[0]), "--limit", "20", "-o",
        str(out / "learned_right_ankle+left_wrist.npz"), "--mirrored",
        str(out / "learned_left_ankle+right_wrist.npz"), "--force"])]


def shin_finish(shared: Path, out: Path) -> list[Step]:
    """The shin ensemble, its mirror and both calibrations, after its four runs."""
    members = [str(out / f"shin{s}.npz") for s in SHIN_SEEDS]
    results = sorted(str(p) for p in CALIBRATION_RESULTS.glob("seeds-*/heldout-contents"))
    steps = [Step("shin ensemble + mirror", ["ensemble", *members, "--data",
                  str(shared / MOTION[0]), "--limit", "20", "-o", str(out / "ensemble.npz"),
                  "--mirrored", str(out / "ensemble_left.npz"), "--force"])]
    for src, dst in (("ensemble.npz", "learned_right_ankle.npz"),
                     ("ensemble_left.npz", "learned_left_ankle.npz")):
        steps.append(Step(f"calibrate {dst}", ["calibrate", *results, "--model",
                          str(out / src), "-o", str(out / dst), "--force"]))
    return steps


def run(step: Step, out: Path) -> Step:
    """Run ``step`` with its output in ``out/<name>.log``; fills in its costs."""
    log = out / (step.name.replace(" ", "_").replace("+", "and") + ".log")
    t0 = time.monotonic()
    with open(log, "w") as f:
        proc = subprocess.Popen(imuloco() + step.args, stdout=f, stderr=subprocess.STDOUT)
        _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    step.wall_s = time.monotonic() - t0
    step.cpu_s = usage.ru_utime + usage.ru_stime
    step.peak_gb = usage.ru_maxrss / 2**20  # kB on Linux
    if proc.returncode:
        raise SystemExit(f"{step.name} failed (exit {proc.returncode}); see {log}")
    print(f"{time.strftime('%H:%M:%S')} done {step.name}: {step.wall_s / 60:.1f} min wall, "
          f"{step.cpu_s / 60:.1f} min CPU", flush=True)
    return step


def weight_distance(a: Path, b: Path) -> float:
    """Largest absolute difference between two model files' common weight arrays."""
    with np.load(a, allow_pickle=False) as fa, np.load(b, allow_pickle=False) as fb:
        # each access to an npz member decompresses it again: read every array once
        x = {k: fa[k] for k in fa.files if not k.startswith("__")}
        y = {k: fb[k] for k in fb.files if k in x}
    pairs = [(x[k], y[k]) for k in y if x[k].shape == y[k].shape and x[k].dtype.kind == "f"]
    return max((float(np.abs(u - v).max()) for u, v in pairs), default=float("nan"))


class LoadSampler(threading.Thread):
    """The 1-minute load average every ``every`` seconds while the run lasts."""

    def __init__(self, every: float = 30.0) -> None:
        super().__init__(daemon=True)
        self.every, self.samples, self.stop = every, [], threading.Event()

    def run(self) -> None:
        while not self.stop.wait(self.every):
            self.samples.append(os.getloadavg()[0])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--shared", type=Path, default=ROOT.parent / "shared" / "data",
                    help="the shared data folder (holds bandai-namco-2, -1, cmu-iclone)")
    ap.add_argument("--out", type=Path, default=Path("train-shipped"),
                    help="folder for the model files and the logs")
    ap.add_argument("--jobs", type=int, default=2, help="trainings at a time")
    ap.add_argument("--dry-run", action="store_true", help="print the commands and stop")
    args = ap.parse_args()
    train, finish = trainings(args.shared, args.out), shin_finish(args.shared, args.out)
    finish_pair = pair_finish(args.shared, args.out)
    if args.dry_run:
        for step in train + finish + finish_pair:
            print(shlex.join(["imuloco", *step.args]))
        return
    missing = [m for m in MOTION + ACTIONS if not (args.shared / m).is_dir()]
    if missing:
        raise SystemExit(f"{args.shared}: no {', '.join(missing)} (give --shared)")
    args.out.mkdir(parents=True, exist_ok=True)
    load = LoadSampler()
    load.start()
    t0 = time.monotonic()
    with ThreadPoolExecutor(args.jobs) as pool:
        shin = [pool.submit(run, s, args.out) for s in train[:len(SHIN_SEEDS)]]
        rest = [pool.submit(run, s, args.out) for s in train[len(SHIN_SEEDS):]]
        for f in shin:
            f.result()
        for step in finish:  # beside the last trainings, in this thread
            run(step, args.out)
        for f in rest:
            f.result()
        for step in finish_pair:
            run(step, args.out)
    finish += finish_pair
    total = time.monotonic() - t0
    load.stop.set()
    print("\n| step | wall min | CPU min | peak GB | max weight difference from the shipped "
          "file |\n|---|---:|---:|---:|---:|")
    for step in train + finish:
        target = Path(step.args[step.args.index("-o") + 1])
        shipped = SHIPPED / target.name
        diff = weight_distance(target, shipped) if shipped.exists() else float("nan")
        print(f"| {step.name} | {step.wall_s / 60:.1f} | {step.cpu_s / 60:.1f} | "
              f"{step.peak_gb:.2f} | {diff:.2g} |")
    cpu = sum(s.cpu_s for s in train + finish)
    loads = load.samples or [float("nan")]
    print(f"\nall shipped weights: {total / 60:.1f} min of wall time, {cpu / 60:.1f} min of CPU "
          f"on {os.cpu_count()} CPUs; load average {np.mean(loads):.1f} "
          f"(min {min(loads):.1f}, max {max(loads):.1f})")


if __name__ == "__main__":
    main()
