"""A saved ``learned`` model's stream step and offline pass, and where a step's time goes.

    python benchmarks/learned_step.py [--model FILE] [--data DIR] [--against REV]
        [--repeat N] [--out DIR]

``imuloco bench --speed`` fits the methods it times (it takes no model file); this times a
saved model, by default the shipped right-shin one, on the speed benchmark's test clip (the
first ``random-clips`` test clip of ``--data``, default the bundled sample; ``phone`` noise,
the test seed) with one BLAS/OpenMP thread, by :mod:`imuloco.lab.speed`'s own timers: CPU
ms a step (p50 over at least 300 steps) and offline frames per CPU second. ``--against REV``:
the same file read by the ``learned`` code of a git commit too, alternating with today's in
one run (``imuloco.lab.speed.method_at``). Then the breakdown of each version's step:
the CPU time of each part :meth:`LearnedStream.step` calls (mean ms a step), timed by wrapping
those functions; ``glue`` is the rest of the step. Prints a markdown table, and writes it with the
figures as ``learned_step.md`` / ``learned_step.json`` under ``--out``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from imuloco.app.pipeline import shipped_model
from imuloco.io.atomic import atomic_write, atomic_write_text
from imuloco.lab import speed
from imuloco.lab.bench import load_data
from imuloco.methods import load_model
from imuloco.methods.training import TEST_SEED_OFFSET, synthesize

SHIPPED = shipped_model("learned", "right_ankle")


def at_revision(model, rev: str):
    """``model`` (a fitted Learned) read by the learned code of git commit ``rev``."""
    old = speed.method_at("learned", rev)(**model.get_params())
    old.set_setup(model.skeleton_, model.fps_, model.placements_, model.noise_)
    old.set_state(*model.get_state())
    return old


def timings(model, test) -> dict[str, float]:
    """CPU ms a step (p50, mean) and offline frames per CPU second of ``model`` on ``test``."""
    _, cpu = speed.time_stream(model, test.signals)
    off = speed.time_offline(model, test)
    return {"step_cpu_ms_p50": float(np.percentile(cpu, 50) * 1e3),
            "step_cpu_ms_mean": float(cpu.mean() * 1e3), "offline_fps_cpu": off["offline_fps_cpu"],
            "test_mpjpe_cm": off["test_mpjpe_cm"]}


def breakdown(model, signals: np.ndarray, steps: int = speed.MIN_STEPS) -> dict[str, float]:
    """Mean CPU ms a step of each part of the stream's step (see the module docstring)."""
    spent: dict[str, float] = defaultdict(float)

    def timed(name, fn):
        def run(*args, **kwargs):
            c0 = time.thread_time()
            try:
                return fn(*args, **kwargs)
            finally:
                spent[name] += time.thread_time() - c0
        return run

    stream = model.stream()
    net = model.net_
    parts = {"inputs": (model, "_inputs"), "network: encode": (net, "encode"),
             "network: heads": (net, "heads"), "novelty": (model, "_novelty"),
             "outputs (de-standardize, sigmoid)": (model, "_outputs"),
             "confidence": (model, "confidence"), "pose integration": (stream.integrator, "step"),
             "foot pinning": (stream.pinner, "step")}
    for name, (obj, attr) in parts.items():  # instance attributes shadow the methods
        setattr(obj, attr, timed(name, getattr(obj, attr)))
    # the kinematics the stream's module calls for the feet (older code: a whole-body fk)
    module = sys.modules[type(model).__module__]
    fk_name = "joint_positions" if hasattr(module, "joint_positions") else "fk"
    feet = getattr(module, fk_name)
    setattr(module, fk_name, timed("foot positions", feet))
    try:
        rows = np.concatenate([signals] * int(np.ceil((steps + speed.WARMUP) / len(signals))))
        for sample in rows[:speed.WARMUP]:
            stream.step(sample)
        spent.clear()
        c0 = time.thread_time()
        for sample in rows[speed.WARMUP:speed.WARMUP + steps]:
            stream.step(sample)
        total = time.thread_time() - c0
    finally:
        setattr(module, fk_name, feet)
        for obj, attr in parts.values():
            delattr(obj, attr)
    out = {k: v / steps * 1e3 for k, v in spent.items()}
    out["glue"] = total / steps * 1e3 - sum(out.values())
    out["total"] = total / steps * 1e3
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", type=Path, default=SHIPPED)
    ap.add_argument("--data", type=Path, default=None, help="clips (default: bundled sample)")
    ap.add_argument("--against", default=None, help="git commit of the code to compare")
    ap.add_argument("--repeat", type=int, default=3, help="timing rounds")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    model = load_model(args.model)
    _, test_db = speed._split_test(load_data(args.data))
    test = synthesize(test_db, model.placements_, "phone", TEST_SEED_OFFSET)[0]
    versions = {"today": model}
    if args.against:
        versions[f"@{args.against}"] = at_revision(model, args.against)
    rows = []
    with threadpool_limits(limits=1):
        for r in range(args.repeat):
            for label, m in versions.items():
                load = os.getloadavg()[0]
                rows.append({"code": label, "round": r, "load_avg": round(load, 2),
                             **timings(m, test)})
        parts = {label: breakdown(m, test.signals) for label, m in versions.items()}
    lines = [(f"`{args.model.name}` ({model.members} network(s), hidden {model.hidden}), "
              f"test clip `{test.labels['name']}`, one thread"), "",
             ("| code | round | CPU ms a step p50 | mean | offline frames/s (CPU) "
              "| test MPJPE cm | load |"), "|---|---:|---:|---:|---:|---:|---:|"]
    lines += [f"| {r['code']} | {r['round']} | {r['step_cpu_ms_p50']:.3f} "
              f"| {r['step_cpu_ms_mean']:.3f} | {r['offline_fps_cpu']:.0f} "
              f"| {r['test_mpjpe_cm']:.4f} | {r['load_avg']:.1f} |" for r in rows]
    lines += ["", "| part of the step, CPU ms (mean) | " + " | ".join(versions) + " |",
              "|---|" + "---:|" * len(versions)]
    lines += [f"| {k} | " + " | ".join(f"{p.get(k, 0.0):.3f} ({p.get(k, 0.0) / p['total']:.0%})"
                                      for p in parts.values()) + " |"
              for k in parts["today"]]
    text = "\n".join(lines)
    print(text)
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        atomic_write_text(args.out / "learned_step.md", text)
        with atomic_write(args.out / "learned_step.json", "w") as f:
            f.write(json.dumps({"model": str(args.model), "timings": rows,
                                "breakdown_ms": parts}, indent=1) + "\n")


if __name__ == "__main__":
    main()
