"""How well two sensors' clocks are aligned by the stomp at the start (imuloco.sensors.multi).

For every clip of the bundled sample: a shin phone and a wrist watch simulated (`phone`
noise) after a still stand with two stomps (`imuloco.sensors.simulate.still_start`,
`add_stomps`), written as one file per sensor with the watch's clock off by each offset
(`imuloco.io.sensorwrite.write_sensor_files`), read back by `read_sensors`. Prints per clip
the error of the offset found (ms) or why it was refused, and the counts: within one frame
(1/30 s), refused, wrong (accepted, off by more than a frame).

    python benchmarks/multi_alignment.py
"""

from __future__ import annotations

import tempfile

from imuloco.errors import ImulocoError
from imuloco.io.database import load_sample
from imuloco.io.sensorwrite import write_sensor_files
from imuloco.sensors.multi import read_sensors
from imuloco.sensors.simulate import STOMP_AT_S, STOMP_LEAD_S, simulate, still_start

OFFSETS = (-2.0, -0.77, 0.5, 1.31, 2.0)
FRAME_S = 1 / 30


def main() -> None:
    counts = {"within a frame": 0, "refused": 0, "wrong": 0}
    for clip in load_sample().clips:
        row = []
        for d in OFFSETS:
            lead = max(d, 0.0)  # the watch starts d s late: the stand and stomps after it
            rec = simulate(still_start(clip, STOMP_LEAD_S + lead), ["right_ankle", "left_wrist"],
                           noise="phone", seed=1, stomps=[lead + t for t in STOMP_AT_S])
            with tempfile.TemporaryDirectory() as tmp:
                files = write_sensor_files(rec, tmp, {"left_wrist": d})
                try:
                    _, rep = read_sensors(files[0], [("left_wrist", files[1])],
                                          placement="right_ankle")
                except ImulocoError as e:
                    counts["refused"] += 1
                    row.append(f"{d:+.2f}: refused ({str(e).split(': ', 2)[-1][:40]})")
                    continue
            err = rep.sensors[1].offset_s - d
            counts["within a frame" if abs(err) <= FRAME_S else "wrong"] += 1
            row.append(f"{d:+.2f}: {1000 * err:+.1f} ms (r {rep.sensors[1].correlation:.2f})")
        print(clip.name, "; ".join(row))
    print(counts)


if __name__ == "__main__":
    main()
