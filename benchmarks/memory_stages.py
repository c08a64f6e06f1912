"""Where ``imuloco reconstruct``'s peak memory goes (issue 43): prints, for one run in this
process, the resident memory (RSS, MB) over time and the imuloco function the main thread was
in when each new high was reached.

    python benchmarks/memory_stages.py LOG [reconstruct options...]

e.g. ``python benchmarks/memory_stages.py walk.csv -o /tmp/w.bvh --report /tmp/w.json
--force``. A thread samples ``/proc/self/statm`` every ``--every`` seconds (default 0.02)
and the main thread's stack (``sys._current_frames``); the table lists each stage (the
outermost imuloco function below the CLI's ``reconstruct``, and the innermost one) with the
largest RSS seen in it. Linux only (``/proc``). A benchmark, not a test: it prints.
"""

from __future__ import annotations

import os
import sys
import threading
import time

PAGE_MB = os.sysconf("SC_PAGE_SIZE") / 2**20


def rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * PAGE_MB


def hwm_mb() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def where(frame) -> tuple[str, str]:
    """(outermost, innermost) imuloco function of a stack, ``module:function``."""
    names = []
    while frame is not None:
        code = frame.f_code
        if "imuloco" in code.co_filename and "cli.py" not in code.co_filename:
            mod = code.co_filename.split("imuloco/")[-1].removesuffix(".py")
            names.append(f"{mod}:{code.co_name}")
        frame = frame.f_back
    return (names[-1], names[0]) if names else ("(outside imuloco)", "")


def main(argv: list[str]) -> None:
    every = 0.02
    if argv[:1] == ["--every"]:
        every, argv = float(argv[1]), argv[2:]
    main_id = threading.get_ident()
    samples: list[tuple[float, float, tuple[str, str]]] = []
    stop = threading.Event()
    t0 = time.perf_counter()

    def sample() -> None:
        while not stop.is_set():
            frame = sys._current_frames().get(main_id)
            samples.append((time.perf_counter() - t0, rss_mb(), where(frame)))
            stop.wait(every)

    print(f"start: {rss_mb():.0f} MB")
    thread = threading.Thread(target=sample, daemon=True)
    thread.start()
    from imuloco.cli import cli  # the CLI's own import (the heavy stack comes on use)

    print(f"after importing the CLI: {rss_mb():.0f} MB")
    try:
        cli.main(["reconstruct", *argv], standalone_mode=False)
    finally:
        stop.set()
        thread.join()
    wall = time.perf_counter() - t0
    stages: dict[tuple[str, str], list[float]] = {}
    for t, mb, key in samples:
        s = stages.setdefault(key, [t, t, 0.0])
        s[1], s[2] = t, max(s[2], mb)
    print(f"wall {wall:.1f} s, CPU {time.process_time():.1f} s, peak (VmHWM) {hwm_mb():.0f} MB, "
          f"end {rss_mb():.0f} MB")
    print("| first s | last s | max RSS MB | outermost | innermost |")
    print("|---:|---:|---:|---|---|")
    top = sorted(stages.items(), key=lambda kv: -kv[1][2])[:25]
    for (outer, inner), (a, b, mb) in sorted(top, key=lambda kv: kv[1][0]):
        print(f"| {a:.1f} | {b:.1f} | {mb:.0f} | {outer} | {inner} |")


if __name__ == "__main__":
    main(sys.argv[1:])
