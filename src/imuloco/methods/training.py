"""Training and test signals: every method synthesizes its sensor data the same way, and
every method reads a recording on the same model-rate frame grid.

A method learns from one explicit input, a :class:`TrainingSet`: the clips with their
signals, the skeleton and frame rate of the output, and the placements and noise the signals
were simulated with (:meth:`TrainingSet.synthesize`). A model validates on the clips
:func:`held_out` picks by name (:func:`held_out_clips`: those a shipped model never saw).
"""

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
from imuloco.core.skeleton import Skeleton
from imuloco.sensors.resample import resample
from imuloco.sensors.simulate import simulate

TEST_SEED_OFFSET = 1_000_003  # test recordings never share a seed with training ones
# share of clips a model holds out (by name hash) for its validation curve: the ``learned``
# method's default ``validation`` and :func:`held_out_clips`'s default share
VALIDATION_SHARE = 0.05
_cache: dict[tuple, tuple[Motion, np.ndarray, float, Recording]] | None = None
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


def held_out(name: str, share: float) -> bool:
    """Whether the clip ``name`` is among the ``share`` of clips a model holds out for its
    validation curve (by CRC32 of the name, so the same clips for every run)."""
    return zlib.crc32(name.encode()) < share * 2**32


def held_out_clips(db: MotionDatabase, share: float | None = None) -> MotionDatabase:
    """The clips of ``db`` that every model of ``share`` (:data:`VALIDATION_SHARE`, the
    ``learned`` method's default ``validation``, when None) holds out for its validation curve
    (:func:`held_out`): the only clips of its training data a shipped model never saw."""
    share = VALIDATION_SHARE if share is None else share
    return db.subset([i for i, c in enumerate(db.labels) if held_out(c["name"], share)])


@dataclass(eq=False)
class Example:
    """One clip with its sensor signals at the clip's frame rate.

    signals : ndarray, shape (T, 6 S): per sensor acc x,y,z (m/s^2) then gyro x,y,z (rad/s),
        one row per motion frame.
    recording : the simulated recording at the sensor's rate the signals were resampled
        from (:func:`synthesize`), what ``imuloco reconstruct`` would read; None where the
        signals came otherwise.
    """

    motion: Motion
    signals: np.ndarray
    labels: dict[str, str]
    recording: Recording | None = None


@dataclass(frozen=True, eq=False)
class TrainingSet:
    """Everything a method learns from (:meth:`imuloco.methods.base.Method.fit_set`).

    examples : the clips with their signals (at least one), all on ``skeleton`` at ``fps``.
    skeleton : the skeleton the method will reconstruct on.
    fps : the model rate, frames per second (the clips' frame rate).
    placements : the sensor placements of the signals, 6 channels each, in this order.
    noise : the noise preset the signals were simulated with.
    seed : the seed of the simulation, when known (recorded with the model).
    """

    examples: tuple[Example, ...]
    skeleton: Skeleton
    fps: float
    placements: tuple[str, ...]
    noise: str
    seed: int | None = None

    def __post_init__(self) -> None:
        if not self.examples:
            raise ValueError("cannot fit on an empty database")
        object.__setattr__(self, "examples", tuple(self.examples))
        object.__setattr__(self, "placements", tuple(self.placements))
        object.__setattr__(self, "fps", float(self.fps))
        width = 6 * len(self.placements)
        bad = [e.labels.get("name", i) for i, e in enumerate(self.examples)
               if e.signals.ndim != 2 or e.signals.shape[1] != width]
        if bad:
            raise ValueError(f"training signals of clip(s) {bad[:3]} are not (T, {width}) "
                             f"for placements {list(self.placements)}")

    @classmethod
    def from_examples(cls, examples: Sequence[Example], placements: Sequence[str],
                      noise: str, seed: int | None = None) -> TrainingSet:
        """A set of already simulated examples; skeleton and rate from the first clip."""
        if not examples:
            raise ValueError("cannot fit on an empty database")
        first = examples[0].motion
        return cls(tuple(examples), first.skeleton, first.fps, tuple(placements), noise, seed)

    @classmethod
    def synthesize(cls, db: MotionDatabase, placements: Sequence[str], noise: str = "phone",
                   seed: int = 0, progress: bool = False) -> TrainingSet:
        """Simulate ``placements`` with ``noise`` on every clip of ``db`` (:func:`synthesize`)."""
        if len(db) == 0:
            raise ValueError("cannot fit on an empty database")
        return cls(tuple(synthesize(db, placements, noise, seed, progress=progress)),
                   db.skeleton, float(db.clips[0].fps), tuple(placements), noise, seed)

    @property
    def num_frames(self) -> int:
        """Frames of all clips together."""
        return sum(e.motion.num_frames for e in self.examples)


def frame_times(rec: Recording, fps: float) -> np.ndarray:
    """The model-rate time grid of a recording, shape (T,), seconds on the recording's clock:
    frames ``1 / fps`` apart from its first sample to (the nearest frame of) its last."""
    frames = round((rec.times[-1] - rec.times[0]) * fps) + 1
    return rec.times[0] + np.arange(frames) / fps


def model_frames(rec: Recording, fps: float, gaps_missing: bool = False) -> np.ndarray:
    """A recording's signals on its model-rate grid (:func:`frame_times`), shape (T, 6 S).

    ``gaps_missing``: frames inside a gap of the recording (no sample for more than 0.1 s,
    :func:`imuloco.sensors.resample.find_gaps`) are rows of NaN instead of interpolated."""
    times = frame_times(rec, fps)
    res, gaps = resample(rec, fps, new_times=times)
    signals = res.channels()
    if gaps_missing:
        for g in gaps:
            signals[(times > g.start) & (times < g.stop)] = np.nan
    return signals


def to_frames(rec: Recording, motion_or_times: Motion | np.ndarray, rate: float | None = None
              ) -> np.ndarray:
    """A recording's signals resampled onto a motion's frame times (or ``times``, seconds
    from the recording's first sample), shape (T, 6 S)."""
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
    signals to the clip's frames (each example keeps its recording too). Each clip's seed
    derives from its name and ``seed``."""
    out = []
    for motion, labels in tqdm(list(db), desc="simulating sensors", disable=not progress,
                               unit="clip"):
        key: tuple[Any, ...] = (id(motion), tuple(placements), noise,
                                clip_seed(labels["name"], seed), rate)
        if _cache is not None and key in _cache:
            signals, seconds, rec = _cache[key][1:]
            _saved[0] += seconds
        else:
            t0 = time.perf_counter()
            rec = simulate(motion, placements, rate, noise, clip_seed(labels["name"], seed))
            signals = to_frames(rec, motion)
            if _cache is not None:  # the motion kept alive keeps its id unique
                _cache[key] = (motion, signals, time.perf_counter() - t0, rec)
        out.append(Example(motion, signals, labels, rec))
    return out
