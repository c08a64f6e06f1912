"""Load test of the live server on 127.0.0.1 (issue #18, "Live server").

    python benchmarks/live_load.py --out docs/results/live [--viewers 100] [--seconds 20]

A server in a child process (the shipped model, no calibration) on a free loopback port; in
this process ``--viewers`` websocket viewers and one phone streaming a simulated walk at real
time, which also sends the abusive messages (a 1 MiB message, 20 x 1000 rows 1e-7 s apart,
2000 messages as fast as it can, a second phone, a viewer that talks). Prints and writes
``load.json``: viewers dropped, poses per second each viewer received, the server's memory
growth, its log lines; then ``dropout.json``: the recovery after 1 s sensor dropouts on
replayed simulated walks (:func:`imuloco.lab.livebench.dropout_recovery`). Linux only (reads
/proc for the server's memory); bounded: one run of ``--seconds``, nine dropout replays.
``imuloco bench live`` runs the same (:func:`imuloco.lab.livebench.live_benchmark`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from imuloco.lab.livebench import live_benchmark, summaries


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="folder for load.json, dropout.json")
    ap.add_argument("--viewers", type=int, default=100)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--no-abuse", action="store_true", help="the phone only streams")
    args = ap.parse_args()
    print(summaries(*live_benchmark(args.out, args.viewers, args.seconds, not args.no_abuse)))


if __name__ == "__main__":
    main()
