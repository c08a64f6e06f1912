"""Training and test signals: every method synthesizes its sensor data the same way."""

from __future__ import annotations

import time
import zlib
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from imuloco.core.motion import Motion, MotionDatabase
from imuloco.core.recording import Recording
from imuloco.sensors.resample import resample
from imuloco.sensors.simulate import simulate

TEST_SEED_OFFSET = 1_000_003  # test recordings never share a seed with training ones
_cache: dict[tuple, tuple[Motion, np.ndarray, float]] | None = None
_saved = [0.0]  # seconds of simulation the cache has saved so far


@contextmanager
def cached_signals() -> Iterator[None]:
    """Within this context :func:`synthesize` simulates each clip once per placements, noise
    and seed and reuses the signals (the bench fits several methods, folds and seeds on the
    same clips). The same numbers as without it: a clip's signals depend on those only.
    :func:`saved_seconds` tells timers how much simulation time the cache saved."""
    global _cache
    outer = _cache
    _cache = {} if outer is None else outer
    try:
        yield
    finally:
        _cache = outer


def saved_seconds() -> float:
    """Simulation seconds :func:`cached_signals` has saved in this process so far (add the
    difference over a fit to its time to get what it would have taken without the cache)."""
    return _saved[0]


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
        key: tuple[Any, ...] = (id(motion), tuple(placements), noise,
                                clip_seed(labels["name"], seed), rate)
        if _cache is not None and key in _cache:
            signals, seconds = _cache[key][1:]
            _saved[0] += seconds
        else:
            t0 = time.perf_counter()
            rec = simulate(motion, placements, rate, noise, clip_seed(labels["name"], seed))
            signals = to_frames(rec, motion)
            if _cache is not None:  # the motion kept alive keeps its id unique
                _cache[key] = (motion, signals, time.perf_counter() - t0)
        out.append(Example(motion, signals, labels))
    return out
