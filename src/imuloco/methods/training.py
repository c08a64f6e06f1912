"""Training and test signals: every method synthesizes its sensor data the same way."""

from __future__ import annotations

import zlib
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from tqdm.auto import tqdm

from imuloco.core.motion import Motion, MotionDatabase
from imuloco.core.recording import Recording
from imuloco.sensors.resample import resample
from imuloco.sensors.simulate import simulate

TEST_SEED_OFFSET = 1_000_003  # test recordings never share a seed with training ones


def clip_seed(name: str, seed: int) -> int:
    """A seed for one clip: stable across runs and machines (CRC32 of the name)."""
    return (zlib.crc32(name.encode()) + seed) % (2**32)


@dataclass(eq=False)
class Example:
    """One clip with its sensor signals at the clip's frame rate.

    signals : ndarray, shape (T, 6 S): per sensor acc x,y,z (m/s^2) then gyro x,y,z (rad/s),
        one row per motion frame.
    """

    motion: Motion
    signals: np.ndarray
    labels: dict[str, str]


def to_frames(rec: Recording, motion_or_times: Motion | np.ndarray, rate: float | None = None
              ) -> np.ndarray:
    """A recording's signals resampled onto a motion's frame times, shape (T, 6 S)."""
    times = motion_or_times.times if isinstance(motion_or_times, Motion) else motion_or_times
    r = rate or 1.0 / np.median(np.diff(times))
    return resample(rec, r, new_times=np.asarray(times) + rec.times[0])[0].channels()


def synthesize(
    db: MotionDatabase,
    placements: Sequence[str],
    noise: str = "phone",
    seed: int = 0,
    rate: float = 100.0,
    progress: bool = False,
) -> list[Example]:
    """Simulate ``placements`` on every clip (at ``rate`` Hz with ``noise``) and resample the
    signals to the clip's frames. Each clip's seed derives from its name and ``seed``."""
    out = []
    for motion, labels in tqdm(list(db), desc="simulating sensors", disable=not progress,
                               unit="clip"):
        rec = simulate(motion, placements, rate, noise, clip_seed(labels["name"], seed))
        out.append(Example(motion, to_frames(rec, motion), labels))
    return out
