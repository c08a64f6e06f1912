"""How well two sensors' clocks are aligned by the stomps at the start (imuloco.sensors.multi).

A shin phone and a wrist watch simulated (`phone` noise) after a still stand with two stomps
(`imuloco.sensors.simulate.still_start`, `add_stomps`), written as one file per sensor with
the clocks apart (`imuloco.io.sensorwrite.write_sensor_files`), read back by `read_sensors`.
Prints per pair the error of the offset found (ms) or why it was refused, and the counts:
within one frame (1/30 s), refused, wrong (accepted, off by more than a frame).

- the default set (the one the rule was tuned on): every clip of the bundled sample (16),
  noise seed 1, the watch's clock off by each of -2, -0.77, +0.5, +1.31, +2 s (for a positive
  offset the watch starts that late; for a negative one both start together, the watch's
  clock reading ahead);
- ``--fresh N``: N clips of each of ``--data``'s folders (evenly spread over their names),
  noise seeds 100 x S on, offsets drawn uniformly in -2..+2 s (``--seed S``, 7 by default),
  the device whose clock is behind starting that late (a negative offset: the phone starts
  late, the watch first); ``--noise`` another preset than `phone`;
- ``--no-stomp``: the same pairs without the stomps (the rule not followed): every one should
  be refused.

    python benchmarks/multi_alignment.py
    python benchmarks/multi_alignment.py --fresh 30 --data ../shared/data/bandai-namco-1 \
        --data ../shared/data/cmu-iclone [--no-stomp]
"""

from __future__ import annotations

import argparse
import tempfile
from collections.abc import Iterator

import numpy as np

from imuloco.core.motion import Motion
from imuloco.errors import ImulocoError
from imuloco.io.database import load_database, load_sample
from imuloco.io.sensorwrite import write_sensor_files
from imuloco.sensors.multi import read_sensors
from imuloco.sensors.simulate import STOMP_AT_S, STOMP_LEAD_S, simulate, still_start

OFFSETS = (-2.0, -0.77, 0.5, 1.31, 2.0)
FRAME_S = 1 / 30
PAIR = ["right_ankle", "left_wrist"]


def tuned_pairs() -> Iterator[tuple[Motion, float, dict[str, float], int]]:
    """(clip, the watch's true offset, each file's clock offset, noise seed)."""
    for clip in load_sample().clips:
        for d in OFFSETS:
            yield clip, d, {"left_wrist": d}, 1


def fresh_pairs(folders: list[str], n: int, draw: int
                ) -> Iterator[tuple[Motion, float, dict, int]]:
    rng = np.random.default_rng(draw)
    seed = 100 * draw
    for folder in folders:
        for clip in load_database(folder, limit=n, progress=False).clips:
            d = float(rng.uniform(-2.0, 2.0))
            yield clip, d, ({"left_wrist": d} if d >= 0 else {"right_ankle": -d}), seed
            seed += 1


def measure(clip: Motion, d: float, clocks: dict[str, float], seed: int, stomp: bool,
            noise: str = "phone") -> tuple[str, str]:
    """(outcome, text) for one pair."""
    lead = max(0.0, *clocks.values())  # the stand and stomps after the later device started
    motion = still_start(clip, STOMP_LEAD_S + lead)
    rec = simulate(motion, PAIR, noise=noise, seed=seed,
                   stomps=[lead + t for t in STOMP_AT_S] if stomp else ())
    with tempfile.TemporaryDirectory() as tmp:
        files = write_sensor_files(rec, tmp, clocks)
        try:
            _, rep = read_sensors(files[0], [("left_wrist", files[1])],
                                  placement="right_ankle")
        except ImulocoError as e:
            why = str(e).split("'s: ", 1)[-1].split(": record with", 1)[0]
            return "refused", f"{d:+.2f}: refused ({why[:70]})"
    err = rep.sensors[1].offset_s - d
    outcome = "within a frame" if abs(err) <= FRAME_S else "wrong"
    return outcome, f"{d:+.2f}: {1000 * err:+.1f} ms (r {rep.sensors[1].correlation:.2f})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--fresh", type=int, default=0, metavar="N")
    ap.add_argument("--data", action="append", default=[])
    ap.add_argument("--seed", type=int, default=7, help="the fresh draw's seed")
    ap.add_argument("--noise", default="phone")
    ap.add_argument("--no-stomp", action="store_true")
    args = ap.parse_args()
    pairs = fresh_pairs(args.data, args.fresh, args.seed) if args.fresh else tuned_pairs()
    counts = {"within a frame": 0, "refused": 0, "wrong": 0}
    errors = []
    for clip, d, clocks, seed in pairs:
        outcome, text = measure(clip, d, clocks, seed, not args.no_stomp, args.noise)
        counts[outcome] += 1
        if outcome != "refused":
            errors.append(abs(float(text.split(": ")[1].split(" ms")[0])))
        print(clip.name, text, flush=True)
    print(counts)
    if errors:
        print(f"|error| ms: median {np.median(errors):.2f}, max {np.max(errors):.2f}")


if __name__ == "__main__":
    main()
