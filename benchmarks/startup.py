"""Start-up time of the command line: each command's ``--help`` and ``imuloco info FILE``.

    python benchmarks/startup.py [--runs 5] [--file MOTION.bvh] [-o TABLE.md]

Runs each command in a fresh process ``--runs`` times (the ``imuloco`` script beside this
Python, else ``python -m imuloco.cli``) and prints a markdown table of the median wall time
and the median CPU time (user + system of the child: the machine is shared, so wall time
includes waiting for a core). Commands are read from :data:`imuloco.cli.cli`, subcommands of a
group (``bench run``, ...) included; ``info FILE`` reads the bundled sample's first clip by
default.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

import click

from imuloco.cli import cli
from imuloco.data import SAMPLE_DIR


def command_paths(group: click.Group, prefix: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """Every command's words under ``group``, groups before their subcommands (hidden ones
    left out)."""
    out = []
    for name, command in sorted(group.commands.items()):
        if command.hidden:
            continue
        out.append((*prefix, name))
        if isinstance(command, click.Group):
            out += command_paths(command, (*prefix, name))
    return out


def program() -> list[str]:
    script = Path(sys.executable).with_name("imuloco")
    return [str(script)] if script.exists() else [sys.executable, "-m", "imuloco.cli"]


def timed(args: list[str], runs: int) -> tuple[float, float]:
    """Median wall and CPU seconds of ``runs`` runs of ``args`` (each must exit 0)."""
    walls, cpus = [], []
    for _ in range(runs):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        subprocess.run(args, check=True, stdout=subprocess.DEVNULL, env=os.environ)
        walls.append(time.perf_counter() - start)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpus.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return statistics.median(walls), statistics.median(cpus)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--file", type=Path, default=min(SAMPLE_DIR.glob("*.bvh")),
                    help="motion file for `imuloco info FILE`")
    ap.add_argument("-o", "--output", type=Path, default=None, help="also write the table here")
    args = ap.parse_args()
    prog = program()
    rows = [("imuloco --help", [*prog, "--help"])]
    rows += [(f"imuloco {' '.join(p)} --help", [*prog, *p, "--help"]) for p in command_paths(cli)]
    rows.append((f"imuloco info {args.file.name}", [*prog, "info", str(args.file)]))
    load = " ".join(f"{v:.2f}" for v in os.getloadavg())
    lines = [f"median of {args.runs} runs; load average before: {load}", "",
             "| command | wall s | CPU s |", "| --- | ---: | ---: |"]
    print("\n".join(lines), flush=True)
    for label, command in rows:
        wall, cpu = timed(command, args.runs)
        lines.append(f"| `{label}` | {wall:.2f} | {cpu:.2f} |")
        print(lines[-1], flush=True)
    if args.output is not None:
        args.output.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
