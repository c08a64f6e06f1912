"""Several sensors written in the layouts the readers take (``imuloco simulate --layout``).

- ``sensorlogger``: a Sensor Logger export folder of an iPhone with an Apple Watch, as the app
  writes it with "Standardise Units & Frames" off: ``Accelerometer.csv`` (gravity removed) and
  ``Gravity.csv`` in m/s^2 and ``Gyroscope.csv`` in rad/s, all with the iOS sign of
  acceleration; ``WristMotion.csv`` (user acceleration and gravity in g, iOS sign, rotation
  rate in rad/s, the attitude quaternion); ``Metadata.csv`` saying ``ios``. Times are Unix ns
  from :data:`SIM_EPOCH_S`: one clock for phone and watch, as in a real export.
- ``files``: one generic CSV per sensor (``PLACEMENT.csv``), each on its own clock when given
  an offset (for ``reconstruct --sensor PLACEMENT=FILE`` and its clock alignment).

The gravity a Core Motion device reports is split from the specific force with the
recording's true orientation (``Recording.orientation``, which simulated recordings carry).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from imuloco.errors import InputError
from imuloco.io.atomic import atomic_write, check_output
from imuloco.io.sensorlog import WATCH_FILE, WATCH_PLACEMENT, write_generic_csv
from imuloco.ops.rotations import qinv, qrot

G = 9.80665
SIM_EPOCH_S = 1_767_225_600.0  # 2026-01-01 00:00 UTC: the simulated export's clock at time 0
_METADATA = "platform,standardisation,sensors\nios,false,{sensors}\n"


def _gravity(rec, k: int) -> np.ndarray:
    """Sensor ``k``'s gravity as a resting accelerometer reads it (+g up), sensor frame,
    m/s^2, shape (T, 3)."""
    if rec.orientation is None:
        raise InputError("writing a Sensor Logger export needs the sensors' orientation "
                         "(a simulated recording has it)")
    up = np.broadcast_to([0.0, G, 0.0], rec.acc[:, k].shape)  # world is Y up
    return qrot(qinv(rec.orientation[:, k]), up)


def _table(path: Path, header: list[str], times: np.ndarray, values: np.ndarray) -> None:
    ns = np.round((SIM_EPOCH_S + times) * 1e9).astype(np.int64)
    with atomic_write(path, "w") as f:
        f.write(",".join(header) + "\n")
        for t, el, row in zip(ns, times, values):
            f.write(f"{t},{el:.6f}," + ",".join(f"{v:.9g}" for v in row) + "\n")


def write_sensor_logger(rec, folder: str | Path, overwrite: bool = False) -> list[Path]:
    """``rec`` (one phone placement, optionally :data:`WATCH_PLACEMENT`) as an iPhone's
    Sensor Logger export folder with the watch's ``WristMotion.csv``; the files written."""
    phone = [p for p in rec.placements if p != WATCH_PLACEMENT]
    if len(phone) != 1 or len(rec.placements) > 2:
        raise InputError(f"a Sensor Logger export holds one phone and at most an Apple Watch "
                         f"at {WATCH_PLACEMENT}; got sensors {rec.placements}")
    folder = Path(folder)
    names = ["Metadata.csv", "Accelerometer.csv", "Gravity.csv", "Gyroscope.csv"]
    if WATCH_PLACEMENT in rec.placements:
        names.append(WATCH_FILE)
    paths = [check_output(folder / n, overwrite) for n in names]
    folder.mkdir(parents=True, exist_ok=True)
    k = rec.placements.index(phone[0])
    g = _gravity(rec, k)
    cols = ["time", "seconds_elapsed", "z", "y", "x"]
    zyx = [2, 1, 0]
    # iOS sign (the opposite of a specific force): Sensor Logger's reader negates it back
    _table(paths[1], cols, rec.times, -(rec.acc[:, k] - g)[:, zyx])
    _table(paths[2], cols, rec.times, -g[:, zyx])
    _table(paths[3], cols, rec.times, rec.gyro[:, k][:, zyx])
    sensors = "Accelerometer|Gravity|Gyroscope"
    if WATCH_PLACEMENT in rec.placements:
        w = rec.placements.index(WATCH_PLACEMENT)
        gw = _gravity(rec, w)
        q = rec.orientation[:, w]
        values = np.concatenate([rec.gyro[:, w], -gw / G, -(rec.acc[:, w] - gw) / G,
                                 q[:, [3, 0, 1, 2]]], axis=1)
        header = ["time", "seconds_elapsed", "rotationRateX", "rotationRateY", "rotationRateZ",
                  "gravityX", "gravityY", "gravityZ", "accelerationX", "accelerationY",
                  "accelerationZ", "quaternionW", "quaternionX", "quaternionY", "quaternionZ"]
        _table(paths[4], header, rec.times, values)
        sensors += "|WristMotion"
    with atomic_write(paths[0], "w") as f:
        f.write(_METADATA.format(sensors=sensors))
    return paths


def write_sensor_files(rec, folder: str | Path, offsets: Mapping[str, float] | None = None,
                       overwrite: bool = False) -> list[Path]:
    """One generic CSV per sensor of ``rec``, ``folder/PLACEMENT.csv``; the files written.

    offsets : seconds a sensor's clock runs behind the recording's (placement -> seconds): its
        file's times are ``rec.times - offset``, and samples before its clock's 0 are left out
        (a device started that much later). ``imuloco reconstruct --sensor`` adds the offset
        back (``sensors[].offset_s``).
    """
    offsets = dict(offsets or {})
    unknown = set(offsets) - set(rec.placements)
    if unknown:
        raise InputError(f"clock offsets for {sorted(unknown)}, which the recording has no "
                         f"sensor at; it has {rec.placements}")
    folder = Path(folder)
    paths = [check_output(folder / f"{p}.csv", overwrite) for p in rec.placements]
    folder.mkdir(parents=True, exist_ok=True)
    for p, path in zip(rec.placements, paths):
        one = rec.select([p])
        t = one.times - offsets.get(p, 0.0)
        keep = t >= 0.0
        one.times, one.acc, one.gyro = t[keep], one.acc[keep], one.gyro[keep]
        one.orientation = None
        write_generic_csv(one, path, overwrite=True)
    return paths
