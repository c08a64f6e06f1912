""":func:`imuloco.methods.postprocess.lock_feet`'s frame loop compiled (numba, the ``fast``
extra): :meth:`~imuloco.methods.postprocess.FootLock.targets` over a whole motion in one call.

The foot lock is a state machine that runs frame by frame (a held point kept until the foot
lifts or slides too far, corrections faded and smoothed causally): it does not vectorise over
frames. As numpy calls on two feet it cost ~140 us a frame (2.6 s for a 640 s walk, the largest
part of a reconstruction after the network); compiled, the same arithmetic costs well under a
microsecond a frame. Hand-written because the lock is imuloco's own; numba only compiles it.
The numpy path (:class:`~imuloco.methods.postprocess.FootLock`, which the online stream runs)
stays the reference and the fallback without numba; they agree to rounding
(tests/test_postprocess.py). Importing this module needs numba; the kernel is compiled on first
use and cached on disk (numba's ``cache=True``), once per machine.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# error_model="numpy": a division by zero gives inf as numpy's does, no exception check
_jit = njit(cache=True, nogil=True, error_model="numpy")

NONE, HEEL, TOE = 0, 1, 2  # what a foot holds


@_jit
def _quat(r: np.ndarray, out: np.ndarray) -> None:
    """Rotation vector (3,) -> quaternion (4,), postprocess._quaternion's formula."""
    angle = math.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
    x = angle / (2.0 * math.pi)
    sinc = 1.0 if x == 0.0 else math.sin(math.pi * x) / (math.pi * x)
    for i in range(3):
        out[i] = r[i] * 0.5 * sinc
    out[3] = math.cos(angle / 2.0)


@_jit
def _rotate(q: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
    """out = q v q* (ops.rotations.qrot: v + w t + u x t, t = 2 u x v)."""
    t0 = 2.0 * (q[1] * v[2] - q[2] * v[1])
    t1 = 2.0 * (q[2] * v[0] - q[0] * v[2])
    t2 = 2.0 * (q[0] * v[1] - q[1] * v[0])
    out[0] = v[0] + q[3] * t0 + (q[1] * t2 - q[2] * t1)
    out[1] = v[1] + q[3] * t1 + (q[2] * t0 - q[0] * t2)
    out[2] = v[2] + q[3] * t2 + (q[0] * t1 - q[1] * t0)


@_jit
def _pitched(d: np.ndarray, pitch: float) -> None:
    """d (3,) turned in place to ``pitch`` against the horizontal (postprocess.pitched)."""
    flat = math.sqrt(d[0] * d[0] + d[2] * d[2])
    length = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    if flat > 1e-9 * max(length, 1e-12):
        scale = length * math.cos(pitch) / max(flat, 1e-12)
        d[0], d[1], d[2] = d[0] * scale, length * math.sin(pitch), d[2] * scale


@_jit
def _between(u: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
    """Rotation vector of the shortest turn from u to v (postprocess._between)."""
    a0 = u[1] * v[2] - u[2] * v[1]
    a1 = u[2] * v[0] - u[0] * v[2]
    a2 = u[0] * v[1] - u[1] * v[0]
    sine = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    if sine > 1e-12:
        k = math.atan2(sine, u[0] * v[0] + u[1] * v[1] + u[2] * v[2]) / max(sine, 1e-12)
        out[0], out[1], out[2] = a0 * k, a1 * k, a2 * k
    else:
        out[0] = out[1] = out[2] = 0.0


@_jit
def lock_targets(feet: np.ndarray, heel: np.ndarray, toe: np.ndarray, threshold: float,
                 hold_flat: bool, smoothing: float, decay: float, slip: np.ndarray,
                 flat_pitch: float, max_turn: float) -> tuple[np.ndarray, np.ndarray]:
    """FootLock.targets and its ``turn`` for every frame from a fresh lock.

    feet : (T, 4, 3) the left and right ankle, then toe; heel, toe : (T, 2) contact
    probabilities; slip : (2,) metres; flat_pitch : radians, NaN for none; max_turn :
    MAX_HOLD_FEET. Returns targets (T, 2, 3) and turns (T, 2, 4).
    """
    n = feet.shape[0]
    targets = np.empty((n, 2, 3))
    turns = np.empty((n, 2, 4))
    held_kind = np.zeros(2, np.int64)
    held = np.zeros((2, 3))
    offset = np.zeros((2, 3))
    applied = np.zeros((2, 3))
    direction = np.full((2, 3), np.nan)
    tilt = np.zeros((2, 3))
    turned = np.zeros((2, 3))
    turn = np.zeros((2, 4))
    turn[:, 3] = 1.0
    foot = np.empty((2, 3))
    tips = np.empty((2, 3))
    flat = np.zeros(2, np.bool_)
    q = np.empty(4)
    v = np.empty(3)
    for t in range(n):
        any_flat, any_turned = False, False
        for s in range(2):
            flat[s] = heel[t, s] > threshold and toe[t, s] > threshold and hold_flat
            any_flat |= flat[s]
            for i in range(3):
                any_turned |= turned[s, i] != 0.0
        # ---- FootLock._turn
        if not (any_flat or any_turned):
            direction[:] = np.nan
            for s in range(2):
                tips[s] = feet[t, 2 + s]
        else:
            for s in range(2):
                for i in range(3):
                    foot[s, i] = feet[t, 2 + s, i] - feet[t, s, i]
            for s in range(2):
                if flat[s] and math.isnan(direction[s, 0]):  # lands
                    _quat(turned[s], q)
                    _rotate(q, foot[s], direction[s])
                    if not math.isnan(flat_pitch):
                        _pitched(direction[s], flat_pitch)
            for s in range(2):
                if not flat[s]:
                    direction[s] = np.nan
                    for i in range(3):
                        tilt[s, i] *= decay
                else:
                    _between(foot[s], direction[s], v)
                    angle = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
                    if angle > max_turn:
                        for i in range(3):
                            v[i] *= max_turn / angle
                        _quat(v, q)
                        _rotate(q, foot[s], direction[s])
                    tilt[s] = v
            for s in range(2):
                big = 0.0
                for i in range(3):
                    turned[s, i] += smoothing * (tilt[s, i] - turned[s, i])
                    big = max(big, abs(turned[s, i]))
                if not flat[s] and big < 1e-9:
                    turned[s] = 0.0
                _quat(turned[s], turn[s])
                _rotate(turn[s], foot[s], v)
                for i in range(3):
                    tips[s, i] = feet[t, s, i] + v[i]
        # ---- FootLock.targets, per side
        for s in range(2):
            kind = (HEEL if heel[t, s] > threshold else TOE if toe[t, s] > threshold
                    else NONE)
            if kind == NONE:
                held_kind[s] = NONE
                for i in range(3):
                    offset[s, i] *= decay
            else:
                point = feet[t, s] if kind == HEEL else tips[s]
                if held_kind[s] != kind:  # lands (or rolls onto its toe) here
                    held_kind[s] = kind
                    for i in range(3):
                        held[s, i] = point[i] + applied[s, i]
                for i in range(3):
                    offset[s, i] = held[s, i] - point[i]
                offset[s, 1] = 0.0
                far = math.sqrt(offset[s, 0] ** 2 + offset[s, 1] ** 2 + offset[s, 2] ** 2)
                if far > slip[s]:
                    for i in range(3):
                        offset[s, i] *= slip[s] / far
                        held[s, i] = point[i] + offset[s, i]
            for i in range(3):
                applied[s, i] += smoothing * (offset[s, i] - applied[s, i])
                targets[t, s, i] = feet[t, s, i] + applied[s, i]
        turns[t] = turn
    return targets, turns
