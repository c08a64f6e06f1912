"""One live walker: raw phone samples in, calibrated model-rate frames through an online method,
joint positions out. No I/O here: :mod:`imuloco.app.live.server` feeds it from a websocket or a
replayed file, and tests feed it directly.

Resampling is causal: frame ``k`` (time ``t0 + k / fps``) is the local linear Gaussian kernel
regression of the raw samples within ``radius`` seconds of it, emitted
as soon as a sample later than ``t_k + radius`` arrives. The kernel width defaults to half a
model period, the anti-aliasing width of :func:`imuloco.sensors.resample.resample` (which the
training signals went through), and ``radius`` to two widths, so the resampling adds one model
period of lag (33 ms at 30 fps). Hand-written because scipy's filters need a uniform grid and
the whole signal; kernel regression handles a phone's irregular timestamps directly, and
:func:`kernel_resample` gives the same frames in one call for offline checks.
"""

from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from imuloco.core.recording import Recording
from imuloco.errors import InputError, MissingExtraError
from imuloco.measures.gait import height_scale
from imuloco.ops.kinematics import fk
from imuloco.ops.rotations import about_y, qmul, qrot
from imuloco.paths.live import RootFollower, StrideStream
from imuloco.paths.registry import ESTIMATORS
from imuloco.sensors.calibration import calibrate, mounting_of
from imuloco.sensors.placement import get_placement

log = logging.getLogger(__name__)

MAX_RATE_HZ = 1000.0  # samples beyond this rate (per second of their own clock) are dropped
RATE_BURST = 100  # samples that may come closer together than that before any is dropped
MAX_GAP_S = 1.0  # a longer pause in the samples is a dropout: the model restarts
DEAD_RECKON_S = 3.0  # the walker moves on through a dropout up to this long, then holds
MIN_CALIBRATE_S = 0.0  # none
MAX_CALIBRATE_S = 60.0  # longest calibration (bounds the calibration buffer)


def _kernel_frame(t: np.ndarray, x: np.ndarray, tk: float, sigma: float, radius: float
                  ) -> np.ndarray:
    """Local linear Gaussian kernel regression at tk of samples x (N, C) at times t (N,) within
    ``radius``; the linear interpolation of the samples around tk when none is that close (a
    gap). Local linear rather than a weighted mean: with irregular timestamps the weighted
    mean is biased by the slope times the samples' mean offset, the line is not."""
    inside = np.abs(t - tk) <= radius
    if not inside.any():
        return np.array([np.interp(tk, t, x[:, c]) for c in range(x.shape[1])])
    d, xs = t[inside] - tk, x[inside]
    w = np.exp(-0.5 * (d / sigma) ** 2)
    s0, s1, s2 = w.sum(), w @ d, w @ d**2
    det = s0 * s2 - s1 * s1
    if det <= 1e-12 * s0 * s2 or len(d) < 3:  # too few samples for a line: weighted mean
        return (w @ xs) / s0
    return (s2 * (w @ xs) - s1 * ((w * d) @ xs)) / det


def kernel_resample(times: np.ndarray, values: np.ndarray, fps: float, sigma: float | None = None,
                    radius: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The frames :class:`KernelResampler` emits for these samples, in one call.

    Parameters
    ----------
    times : ndarray, shape (N,), seconds, increasing.
    values : ndarray, shape (N, C).
    fps : frame rate of the output grid, which starts at ``times[0]``.
    sigma, radius : kernel width and support in seconds (default ``0.5 / fps`` and
        ``2 * sigma``).

    Returns
    -------
    frame times (K,) and frames (K, C): every grid time ``t_k`` with ``t_k + radius`` before the
    last sample.
    """
    times, values = np.asarray(times, dtype=np.float64), np.asarray(values, dtype=np.float64)
    sigma = 0.5 / fps if sigma is None else sigma
    radius = 2.0 * sigma if radius is None else radius
    n = int(np.ceil((times[-1] - radius - times[0]) * fps - 1e-9)) if len(times) else 0
    grid = times[0] + np.arange(max(n, 0)) / fps
    grid = grid[grid + radius < times[-1]]
    frames = np.empty((len(grid), values.shape[1]))
    for k, tk in enumerate(grid):
        lo = max(np.searchsorted(times, tk - radius, side="left") - 1, 0)
        hi = np.searchsorted(times, tk + radius, side="right") + 1
        frames[k] = _kernel_frame(times[lo:hi], values[lo:hi], tk, sigma, radius)
    return grid, frames


class TokenBucket:
    """At most ``rate`` units per second on average and ``burst`` at once, on a clock the
    caller gives (stream time or wall time). Ten lines rather than a library: the rate
    limiters on PyPI (aiolimiter, limits) wait on the wall clock, not on a sender's timestamps.
    """

    def __init__(self, rate: float, burst: float) -> None:
        self.rate, self.burst = rate, burst
        self.level, self.t = float(burst), None

    def take(self, now: float, amount: float = 1.0) -> bool:
        """Whether ``amount`` more fit at time ``now`` (seconds); if so they are taken."""
        if self.t is not None:
            self.level = min(self.burst, self.level + max(now - self.t, 0.0) * self.rate)
        self.t = now
        if self.level < amount:
            return False
        self.level -= amount
        return True


class KernelResampler:
    """Online :func:`kernel_resample`: push samples one at a time, get the frames they complete.

    Holds only the samples within ``radius`` of the next frame (plus one before, for gaps).
    """

    def __init__(self, fps: float, sigma: float | None = None, radius: float | None = None):
        self.fps = fps
        self.sigma = 0.5 / fps if sigma is None else sigma
        self.radius = 2.0 * self.sigma if radius is None else radius
        self.t0: float | None = None
        self.next = 0  # index of the next frame to emit
        self.buf: deque[tuple[float, np.ndarray]] = deque()

    def push(self, t: float, x: np.ndarray) -> list[tuple[int, float, np.ndarray]]:
        """Add one sample (C,) at time t (after the previous one); returns the completed
        frames as (index, time, values (C,))."""
        if self.t0 is None:
            self.t0 = t
        self.buf.append((t, np.asarray(x, dtype=np.float64)))
        out = []
        while True:
            tk = self.t0 + self.next / self.fps
            if not tk + self.radius < t:
                break
            ts = np.array([s[0] for s in self.buf])
            xs = np.stack([s[1] for s in self.buf])
            out.append((self.next, tk, _kernel_frame(ts, xs, tk, self.sigma, self.radius)))
            self.next += 1
            # keep one sample before the next frame's support
            tn = self.t0 + self.next / self.fps - self.radius
            while len(self.buf) > 1 and self.buf[1][0] < tn:
                self.buf.popleft()
        return out

    def skip_to(self, t: float) -> None:
        """Forget the samples held and go on with the first grid frame at or after t (the
        frames of a dropout are skipped, the grid stays the same)."""
        self.buf.clear()
        if self.t0 is not None:
            self.next = max(self.next, int(np.ceil((t - self.t0) * self.fps - 1e-9)))


@dataclass
class Frame:
    """One reconstructed frame.

    index : model frame number from the first sample; time : its time, seconds on the sender's
    clock; trigger : time of the sample whose arrival completed it (for a model with
    look-ahead, ``delay_frames`` frames later); rotations : (J, 4) local
    quaternions x, y, z, w; root : (3,) metres; positions : (J, 3) world joint positions,
    metres, Y up (root and positions in the session's height, see :class:`LiveSession`);
    error_m : the method's predicted rms joint position error of the frame, metres, in the
    session's height too (NaN: the method gives none); unreliable : the method flags the frame
    (it does not know the motion); see :class:`imuloco.methods.base.Stream`.
    """

    index: int
    time: float
    trigger: float
    rotations: np.ndarray
    root: np.ndarray
    positions: np.ndarray
    error_m: float = float("nan")
    unreliable: bool = False


@dataclass
class Calibration:
    """Per sensor phone-to-segment rotations (S, 4) found on the first ``samples`` samples."""

    rotations: np.ndarray
    samples: int
    seconds: float
    details: list[dict] = field(default_factory=list)


class LiveSession:
    """Calibrate, resample and reconstruct one walker's samples as they arrive.

    Parameters
    ----------
    method : a fitted method with ``supports_online``; its ``placements_`` are the sensors
        every sample carries, in order.
    calibrate_s : seconds of samples to calibrate how the phone sits on the leg
        (:func:`imuloco.sensors.calibration.calibrate`); the first frames come out then. While
        a leg or lower-back sensor shows fewer than two strides the calibration waits up to
        three times as long for the walk to start. ``0`` skips calibration (phone strapped in
        the segment's anatomical frame). At most :data:`MAX_CALIBRATE_S`.
    sigma_s, radius_s : resampling kernel (see the module docstring).
    calibration : a calibration found earlier for the same phone (skips calibrating).
    max_gap_s : a longer pause between samples is a dropout (see :meth:`push`).
    height_m : the wearer's body height in metres: the skeleton and the root path are scaled
        to it as :func:`imuloco.measures.gait.to_height` scales a reconstruction (``None``: the
        model skeleton's proportions).
    follow_path : the root follows the path the first placement with a path estimator
        measures (:mod:`imuloco.paths.live`: strides confirmed as their end footfall is
        detected, the root between them carried on at the last stride's gain and corrected
        smoothly); False: the model's own root. No frame waits for it: the delay is the same.
    path_background : the path's estimate runs on a thread of its own (the server), not
        inline in :meth:`push` (deterministic: tests and benches).

    Bounded state: samples beyond ``MAX_RATE_HZ`` per second of their own timestamps (after a
    burst of ``RATE_BURST``) are dropped and counted in :attr:`dropped`, so the calibration
    buffer holds at most ``(3 calibrate_s + 1) MAX_RATE_HZ + RATE_BURST`` samples and the
    resampler about a hundred, whatever the timestamps.
    """

    def __init__(self, method, calibrate_s: float = 5.0, sigma_s: float | None = None,
                 radius_s: float | None = None, calibration: Calibration | None = None,
                 max_gap_s: float = MAX_GAP_S, height_m: float | None = None,
                 follow_path: bool = True, path_background: bool = False) -> None:
        if not (getattr(method, "supports_online", False)
                and getattr(method, "can_stream", lambda: True)()):
            raise InputError(f"method {method.name!r} has no online mode as configured; live "
                             "needs one of the methods `imuloco methods` lists as online "
                             "(a learned model: causal, not bidirectional)")
        if not MIN_CALIBRATE_S <= calibrate_s <= MAX_CALIBRATE_S:
            raise ValueError(f"calibrate_s must be between 0 and {MAX_CALIBRATE_S:g} seconds, "
                             f"got {calibrate_s}")
        self.method = method
        self.placements = list(method.placements_)
        self.calibrate_s = calibrate_s
        self.max_gap_s = max_gap_s
        self.height_m = height_m
        self.scale = 1.0 if height_m is None else height_scale(method.skeleton_, height_m)
        self.skeleton = method.skeleton_.scaled(self.scale)  # the skeleton frames are posed on
        self.stream = method.stream()
        self.resampler = KernelResampler(float(method.fps_), sigma_s, radius_s)
        self.calibration = calibration
        # raw samples while calibrating: rows (t, acc (S*3), gyro (S*3)), preallocated
        cap = 0 if calibration is not None else int((3 * calibrate_s + 1) * MAX_RATE_HZ)
        self._raw = np.empty((cap + RATE_BURST + 1, 1 + 6 * self.num_sensors))
        self._rate = TokenBucket(MAX_RATE_HZ, RATE_BURST)
        self._n = 0
        self._next_try = calibrate_s
        self.last_t: float | None = None
        self.dropped = 0  # samples not after the previous one, or beyond MAX_RATE_HZ
        self.dropouts = 0  # pauses longer than max_gap_s
        self._first_k = 0  # resampler frames before this one are not shown (after a dropout)
        self._turn = np.array([0.0, 0.0, 0.0, 1.0])  # (4,) yaw applied to the stream's output
        self._shift = np.zeros(3)  # (3,) metres added to the stream's root after _turn
        self._recent: deque[tuple[float, np.ndarray, float]] = deque(
            maxlen=int(np.ceil(method.fps_)) + 1)  # (time, root, yaw) of the last second
        self._join: float | None = None  # time of the last frame before a dropout
        self.path_placement = _path_placement(self.placements) if follow_path else None
        self.strides: StrideStream | None = None  # the path's strides, causally
        self.follower: RootFollower | None = None  # the root on them
        if self.path_placement is not None:
            self.strides = StrideStream(self.path_placement, height_m,
                                        background=path_background)
            self.follower = RootFollower(float(method.fps_))

    @property
    def num_sensors(self) -> int:
        return len(self.placements)

    @property
    def calibrating(self) -> bool:
        return self.calibration is None and self.calibrate_s > 0

    @property
    def buffered(self) -> int:
        """Raw samples held (calibration buffer and resampler): bounded, see the class."""
        return self._n + len(self.resampler.buf)

    def close(self) -> None:
        """Stop the path's estimate thread, if any (the session is done)."""
        if self.strides is not None:
            self.strides.close()

    def calibration_progress(self) -> tuple[float, float] | None:
        """While calibrating, (seconds of samples held, seconds it wants); else None."""
        if not self.calibrating:
            return None
        return (float(self.last_t - self._raw[0, 0]) if self._n else 0.0), self.calibrate_s

    def describe(self) -> str:
        """One line for the user: calibration progress or the frame count."""
        if self.calibrating:
            span = self.calibration_progress()[0]
            wait = "walk a few steps" if span > self.calibrate_s else "stand still, then walk"
            return f"calibrating: {span:.1f} s of {self.calibrate_s:g} s ({wait})"
        return f"streaming: frame {self.resampler.next}"

    def push(self, t: float, acc: np.ndarray, gyro: np.ndarray) -> list[Frame]:
        """One sample: t seconds, acc (S, 3) m/s^2 and gyro (S, 3) rad/s in the phone's axes.

        Returns the frames it completes (none while calibrating, a burst when it ends). After
        a dropout (more than ``max_gap_s`` without samples) the model restarts on fresh state
        while the walker carries on: frame numbers keep counting on the same grid, it keeps its
        heading, and moves on at the mean velocity of the second before the pause (held still
        after a pause over :data:`DEAD_RECKON_S`). Of the ways tried on the sample's walks (held
        still; velocity; velocity and turn rate, from end points or fitted lines) this one
        started nearest the run without the pause (0.29 m and 13 degrees apart on average over
        ten 1 s dropouts, 0.3 s after them). A dropout while calibrating
        restarts the calibration.
        """
        acc = np.asarray(acc, dtype=np.float64).reshape(self.num_sensors, 3)
        gyro = np.asarray(gyro, dtype=np.float64).reshape(self.num_sensors, 3)
        if (self.last_t is not None and t <= self.last_t) or not self._rate.take(t):
            self.dropped += 1
            return []
        if self.last_t is not None and t - self.last_t > self.max_gap_s:
            self._dropout(t)
        self.last_t = t
        if self.calibrating:
            return self._calibration_sample(t, acc, gyro)
        return self._feed(t, acc, gyro)

    def _calibration_sample(self, t: float, acc: np.ndarray, gyro: np.ndarray) -> list[Frame]:
        self._raw[self._n] = np.concatenate([[t], acc.ravel(), gyro.ravel()])
        self._n += 1
        full = self._n == len(self._raw)  # cannot happen within MAX_RATE_HZ; a safeguard
        if not full and (t - self._raw[0, 0] < self._next_try or not self._calibrate()):
            return []
        if full and self.calibration is None:
            self._calibrate(final=True)
        raw, n, s = self._raw, self._n, self.num_sensors
        self._raw, self._n = np.empty((0, raw.shape[1])), 0
        frames = [f for r in raw[:n] for f in self._feed(r[0], r[1:1 + 3 * s].reshape(s, 3),
                                                            r[1 + 3 * s:].reshape(s, 3))]
        for f in frames:  # all completed by this sample's arrival
            f.trigger = t
        return frames

    def _dropout(self, t: float) -> None:
        self.dropouts += 1
        if self.calibrating:  # start calibrating again on the samples after the pause
            self._n, self._next_try = 0, self.calibrate_s
            return
        self.stream = self.method.stream()
        if self.strides is not None:
            self.strides.reset()
            self.follower.restart()
        self.resampler.skip_to(t)
        self._first_k = self.resampler.next
        self._join = self._recent[-1][0] if self._recent else None

    def _calibrate(self, final: bool = False) -> bool:
        raw, s = self._raw[:self._n], self.num_sensors
        t = raw[:, 0]
        rec = Recording(t, raw[:, 1:1 + 3 * s].reshape(-1, s, 3),
                        raw[:, 1 + 3 * s:].reshape(-1, s, 3), self.placements)
        try:
            _, mounts = calibrate(rec)
        except (ValueError, np.linalg.LinAlgError, MissingExtraError) as e:  # e.g. no swing yet
            mounts, why = None, f"{type(e).__name__}: {e}"
        else:
            walked = [m for p, m in zip(self.placements, mounts) if mounting_of(p)]
            why = "fewer than two strides" if any(m.swings < 2 for m in walked) else ""
        span = t[-1] - t[0]
        if why and span < 3 * self.calibrate_s and not final:
            self._next_try = span + 1.0
            return False
        if mounts is None:
            log.warning("calibration failed (%s): the phone's axes are used as they are", why)
            rot = np.tile([0.0, 0.0, 0.0, 1.0], (self.num_sensors, 1))
            details = []
        else:
            rot = np.stack([m.rotation for m in mounts])
            details = [{"placement": p, "up_from": m.up_source, "still_s": round(m.still_s, 2),
                        "swings": m.swings} for p, m in zip(self.placements, mounts)]
        self.calibration = Calibration(rot, len(t), float(span), details)
        return True

    def _feed(self, t: float, acc: np.ndarray, gyro: np.ndarray) -> list[Frame]:
        if self.calibration is not None:
            acc = qrot(self.calibration.rotations, acc)
            gyro = qrot(self.calibration.rotations, gyro)
        row = np.concatenate([acc, gyro], axis=-1).reshape(-1)  # (6S,) as Recording.channels
        sk = self.skeleton
        out = []
        if self.strides is not None:
            j = self.placements.index(self.path_placement)
            self.strides.push(t, acc[j], gyro[j])
            for stride in self.strides.poll():
                self.follower.add(stride)
        d = self.stream.delay_frames  # a model with look-ahead returns frame k - d
        for k, tk, x in self.resampler.push(t, row):
            rot, root = self.stream.step(x)
            root = root * self.scale
            if k < self._first_k + d:
                continue
            tf = tk - d / self.resampler.fps
            if self._join is not None:
                self._continue_walker(tf, rot, root)
            rot, root = rot.copy(), qrot(self._turn, root) + self._shift
            rot[0] = qmul(self._turn, rot[0])
            if self.follower is not None:
                root[[0, 2]] = self.follower.step(tf, root[[0, 2]], self.strides.still())
            self._recent.append((tf, root, float(_yaw(rot[0]))))
            pos = fk(rot, root, sk.offsets, sk.parents)[1]
            out.append(Frame(k - d, tf, t, rot, root, pos,  # a duck-typed stream may lack them
                             float(getattr(self.stream, "error_m", math.nan)) * self.scale,
                             bool(getattr(self.stream, "unreliable", False))))
        return out

    def _continue_walker(self, t: float, rot: np.ndarray, root: np.ndarray) -> None:
        """Set the turn and shift that put the restarted model's first frame (local rotations
        rot (J, 4), root (3,) at time t) where the walker would be had it kept its heading and
        the velocity of the second before the dropout (see :meth:`push`)."""
        t0 = self._join
        self._join = None
        times = np.array([r[0] for r in self._recent])
        keep = times > t0 - 1.0
        times, roots = times[keep], np.stack([r[1] for r in self._recent])[keep]
        target, yaw = roots[-1], self._recent[-1][2]
        if len(times) > 1 and t - t0 <= DEAD_RECKON_S:  # on at the last second's velocity
            target = target + (roots[-1] - roots[0]) / (times[-1] - times[0]) * (t - t0)
        self._turn = about_y(np.asarray(yaw - _yaw(rot[0])))
        self._shift = target - qrot(self._turn, root)
        if self.follower is not None:  # the follower's offset is added after the shift
            self._shift[[0, 2]] -= self.follower.offset
        self._shift[1] = 0.0  # the model's own root height


def _path_placement(placements: list[str]) -> str | None:
    """The first of ``placements`` with a path estimator whose extra is installed (a missing
    one is logged: the root is then the model's)."""
    for p in placements:
        if p in ESTIMATORS:
            try:
                get_placement(p).require_extra()
            except MissingExtraError as e:
                log.warning("the live root does not follow %s's path: %s", p, e)
                continue
            return p
    return None


def _yaw(q: np.ndarray) -> float:
    """Heading (radians about +Y, 0 facing +Z, as :mod:`imuloco.ops.heading`) of a root
    rotation q (4,)."""
    forward = qrot(q, np.array([0.0, 0.0, 1.0]))
    return float(np.arctan2(forward[0], forward[2]))


def offline_frames(times: np.ndarray, acc: np.ndarray, gyro: np.ndarray, fps: float,
                   rotations: np.ndarray | None = None, sigma: float | None = None,
                   radius: float | None = None) -> np.ndarray:
    """The signal frames (K, 6 S) a :class:`LiveSession` feeds its stream, computed in one go.

    times (N,), acc and gyro (N, S, 3) raw samples; rotations (S, 4) the calibration.
    """
    if rotations is not None:
        acc, gyro = qrot(rotations, acc), qrot(rotations, gyro)
    chans = np.concatenate([acc, gyro], axis=-1).reshape(len(times), -1)
    return kernel_resample(times, chans, fps, sigma, radius)[1]


def frames_to_json(frames: Sequence[Frame]) -> list[dict]:
    """Pose messages: joint positions in millimetres (0.1 mm), flattened (J * 3); ``error_m``
    the frame's predicted error in metres (0.1 mm; ``None`` when the method gives none) and
    ``unreliable`` whether the method flags it."""
    return [{"type": "pose", "frame": f.index, "t": round(f.time, 4), "trigger": f.trigger,
             "positions": np.round(f.positions * 1000.0, 1).ravel().tolist(),
             "error_m": round(f.error_m, 4) if np.isfinite(f.error_m) else None,
             "unreliable": f.unreliable} for f in frames]
