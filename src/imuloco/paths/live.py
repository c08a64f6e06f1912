"""The path, causally: the live avatar's root follows the measured path (issue 40, live mode).

Two pieces, both fed in time order and holding bounded state:

- :class:`StrideStream`, every path estimator's streaming form: the placement's own estimator
  (:mod:`imuloco.paths.registry`, the code the offline path runs) re-run every ``hop_s`` on
  the last ``window_s`` seconds of samples. A stride is *confirmed* once its end footfall lies
  ``settle_s`` before the newest sample (detected with the next swing under way, not guessed
  at the window's edge) and after the last confirmed stride's end: each stride is read once,
  about ``settle_s`` to ``settle_s + hop_s`` after its end footfall. The estimate may run
  inline (deterministic: tests, benches) or on a thread of its own (the server: frames never
  wait for it).
- :class:`RootFollower`, the causal form of :func:`imuloco.paths.follow.follow`'s rule for a
  path known by its stride lengths: the root keeps the model's own direction, its horizontal
  steps scaled by the gain of the last confirmed strides (their lengths over the model's own
  root displacement during them, GAIN_STRIDES strides together). Between footfalls the root
  is thus carried on at the last strides' gain; when the next stride is confirmed, the
  distance the frames since those strides' start should have covered at the new gain, less
  what they did, is blended in over ``blend_s`` or more (a smoothstep, at most
  MAX_CORRECTION_MPS on average: no jump; at most ``1.5 |error| / (blend fps)`` more in
  one frame).

While the sensor is still (its gyroscope below STILL_RAD_S for STILL_HOLD_S: standing, not a
walking stance) the root holds where it is, whatever the model's own root does: the offline
path stands there too, and a model that never saw standing walks on (ridge on the bundled
sample: 34 m over a 30 s pause after a walk; with the path followed it walked 33 m before
this rule, 0 after it).

The live avatar so covers the distance the offline path does (up to the stride still under
way at the end); the pose above the root is the model's.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np

from imuloco.core.recording import Recording
from imuloco.errors import ImulocoError, MissingExtraError, UnknownNameError
from imuloco.paths.base import Stride
from imuloco.paths.follow import MAX_GAIN
from imuloco.paths.registry import ESTIMATORS, estimate_path

WINDOW_S = 12.0  # samples re-estimated: mobgap's gait sequences need several seconds of walk
HOP_S = 1.0  # how often the estimate runs (stream seconds)
SETTLE_S = 0.6  # a stride ends this long before the newest sample before it is read
BLEND_S = 0.5  # a confirmed stride's correction is spread over this long
MAX_CORRECTION_MPS = 0.5  # ... or longer: a correction moves the root at most this fast
GAIN_STRIDES = 2  # the gain is that of the last strides together (one stride's own
#                   displacement depends on where its footfalls were found: 0.1-0.2 s jitter)
MIN_OWN_M = 0.05  # the model moved less over a stride: its gain is not defined (kept)
STILL_RAD_S = 0.2  # the sensor still: its gyroscope's norm below this (the shank pivot's)
STILL_HOLD_S = 0.8  # ... for this long: longer than a foot's flat phase walking slowly


class StrideStream:
    """A placement's path estimator on a sliding window (module docstring).

    Parameters
    ----------
    placement : a placement with a path estimator (:data:`imuloco.paths.registry.ESTIMATORS`).
    height_m : the walker's height (``--height``), as the offline estimator takes it.
    window_s, hop_s, settle_s : see the module docstring.
    background : run the estimate on a thread of its own (its strides are read at the first
        :meth:`poll` after it ends) rather than inline in :meth:`poll`.
    """

    def __init__(self, placement: str, height_m: float | None = None,
                 window_s: float = WINDOW_S, hop_s: float = HOP_S, settle_s: float = SETTLE_S,
                 background: bool = False) -> None:
        if placement not in ESTIMATORS:
            raise UnknownNameError(f"no path estimator for placement {placement!r}; have "
                                   f"{sorted(ESTIMATORS)}")
        self.placement, self.height_m = placement, height_m
        self.window_s, self.hop_s, self.settle_s = window_s, hop_s, settle_s
        self.samples: deque[tuple[float, np.ndarray]] = deque()  # (t, acc and gyro (6,))
        self.foot: str | None = None  # the foot whose strides are read (the first seen)
        self.last_end = -math.inf  # the last confirmed stride's end, seconds
        self.runs = 0  # estimates run
        self.read: deque[tuple[Stride, float]] = deque(maxlen=1000)  # (stride, read at, s)
        self._due: float | None = None  # stream time of the next estimate
        self._still_since: float | None = None  # the first sample of the still run under way
        self._newest = -math.inf
        self._pool = ThreadPoolExecutor(1, "imuloco-live-path") if background else None
        self._job: Future | None = None

    def push(self, t: float, acc: np.ndarray, gyro: np.ndarray) -> None:
        """One sample: t seconds (after the previous), acc (3,) m/s^2, gyro (3,) rad/s."""
        self.samples.append((t, np.concatenate([acc, gyro])))
        self._newest = t
        if not np.linalg.norm(gyro) < STILL_RAD_S:  # moving (or NaN)
            self._still_since = None
        elif self._still_since is None:
            self._still_since = t
        while self.samples[0][0] < t - self.window_s:
            self.samples.popleft()
        if self._due is None:
            self._due = t + self.hop_s

    def poll(self) -> list[Stride]:
        """The strides confirmed since the last call (times in the samples' clock), oldest
        first; starts the estimate when it is due."""
        out: list[Stride] = []
        if self._job is not None and self._job.done():
            out, self._job = self._confirm(*self._job.result()), None
        if self._due is not None and self.samples[-1][0] >= self._due and self._job is None:
            self._due = self.samples[-1][0] + self.hop_s
            t = np.array([s[0] for s in self.samples])
            x = np.stack([s[1] for s in self.samples])
            if self._pool is None:
                out += self._confirm(*self._estimate(t, x))
            else:
                self._job = self._pool.submit(self._estimate, t, x)
        return out

    def _estimate(self, t: np.ndarray, x: np.ndarray) -> tuple[list[Stride], float]:
        self.runs += 1
        if t[-1] - t[0] < 2.0:
            return [], t[-1]
        rec = Recording(t, x[:, None, :3], x[:, None, 3:], [self.placement])
        try:
            path = estimate_path(rec, self.placement, self.height_m)
        except MissingExtraError:
            raise
        except (ImulocoError, ValueError, np.linalg.LinAlgError):
            return [], t[-1]  # no walk in the window (yet): no stride
        return [dataclasses.replace(s, start_s=s.start_s + t[0], end_s=s.end_s + t[0])
                for s in path.strides], float(t[-1])

    def _confirm(self, strides: list[Stride], newest: float) -> list[Stride]:
        out = []
        for s in sorted(strides, key=lambda s: s.end_s):
            if self.foot is None:
                self.foot = s.foot
            # a stride starting before the last read one's end (by more than a footfall's
            # jitter, 0.2 s) is one already read, its footfall found again
            if (s.foot != self.foot or s.end_s > newest - self.settle_s
                    or s.start_s < self.last_end - 0.2 or not math.isfinite(s.length_m)):
                continue
            out.append(s)
            self.read.append((s, newest))
            self.last_end = s.end_s
        return out

    def still(self) -> bool:
        """Whether the sensor has been still for STILL_HOLD_S up to the newest sample (the
        module docstring; False before any sample)."""
        return self._still_since is not None and self._newest - self._still_since >= STILL_HOLD_S

    def reset(self) -> None:
        """Forget the samples (after a dropout: a window across the gap is not a walk)."""
        self.samples.clear()
        self._due = None
        self._still_since = None

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)


class RootFollower:
    """The live root's horizontal offset from the model's (module docstring).

    fps : frames per second of the roots stepped; blend_s : a correction's ramp, seconds;
    history_s : seconds of frames kept to read a confirmed stride's own displacement.
    """

    def __init__(self, fps: float, blend_s: float = BLEND_S,
                 history_s: float = WINDOW_S + 5.0) -> None:
        self.fps, self.blend_s = fps, blend_s
        self.gain = 1.0
        self.offset = np.zeros(2)  # (2,) metres added to the model's root (X, Z)
        # frames: (time, the model's root (2,), its step (2,), the gain the step got);
        # read strides: (start, length, the model's own displacement over it)
        self.frames: deque[list] = deque(maxlen=max(2, int(history_s * fps)))
        self._prev: np.ndarray | None = None
        self._pending = np.zeros(2)  # the correction being blended in, metres
        self._ramp = 1.0  # how much of it is in (0..1)
        self._blend = blend_s  # its ramp's length, seconds
        self._read: deque[tuple[float, float, float]] = deque(maxlen=GAIN_STRIDES)

    def step(self, t: float, root_xz: np.ndarray, still: bool = False) -> np.ndarray:
        """The followed root (2,) (X, Z) of the model's ``root_xz`` (2,) at time ``t``;
        ``still``: the sensor is still (:meth:`StrideStream.still`), the root holds (but for
        a correction being blended in)."""
        root_xz = np.asarray(root_xz, float)
        d = np.zeros(2) if self._prev is None else root_xz - self._prev
        self._prev = root_xz.copy()
        gain = 0.0 if still else self.gain
        self.offset += (gain - 1.0) * d
        if self._ramp < 1.0:
            r = min(1.0, self._ramp + 1.0 / (self._blend * self.fps))
            self.offset += self._pending * (_smoothstep(r) - _smoothstep(self._ramp))
            self._ramp = r
        self.frames.append([t, root_xz.copy(), d, gain])
        return root_xz + self.offset

    def add(self, stride: Stride) -> None:
        """A confirmed stride: the gain from now on, and the correction of the frames since the
        last strides' start blended in (module docstring). A stride older than the frames kept
        is left out."""
        if not self.frames or stride.start_s < self.frames[0][0]:
            return
        times = np.array([f[0] for f in self.frames])
        roots = np.stack([f[1] for f in self.frames])
        a, b = np.searchsorted(times, [stride.start_s, stride.end_s])
        b = min(b, len(times) - 1)
        if b <= a:
            return
        self._read.append((stride.start_s, stride.length_m,
                           float(np.linalg.norm(roots[b] - roots[a]))))
        own = sum(r[2] for r in self._read)
        if own < MIN_OWN_M * len(self._read):
            return
        gain = float(np.clip(sum(r[1] for r in self._read) / own, 1.0 / MAX_GAIN, MAX_GAIN))
        first = int(np.searchsorted(times, self._read[0][0]))
        error = np.zeros(2)
        for f in list(self.frames)[first + 1:]:  # the steps since the strides' start
            if f[3] == 0.0:  # held still (gains are at least 1 / MAX_GAIN otherwise)
                continue
            error += (gain - f[3]) * f[2]
            f[3] = gain
        self._pending = self._pending * (1.0 - _smoothstep(self._ramp)) + error
        self._blend = max(self.blend_s, float(np.linalg.norm(self._pending)) / MAX_CORRECTION_MPS)
        self._ramp = 0.0
        self.gain = gain

    def restart(self) -> None:
        """The model restarted (a dropout): its next root is no step from the last."""
        self._prev = None


def _smoothstep(r: float) -> float:
    """3 r^2 - 2 r^3: 0 to 1 with zero slope at both ends (slope at most 1.5)."""
    return r * r * (3.0 - 2.0 * r)
