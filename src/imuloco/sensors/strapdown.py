"""Strapdown integration of one IMU between moments its velocity is known.

Hand-written because no maintained library does this piece: gaitmap's ``RtsKalman`` assumes the
sensor itself is still at its zero-velocity updates, whereas a shank sensor is not (it pivots
about the still ankle, so its velocity there is ``omega x r``). The orientation is the
gyroscope integrated (scipy ``Rotation``), its tilt reset by gravity at each anchor (where the
limb is in stance and the accelerometer reads gravity up to the small pivot accelerations);
the velocity is the gravity-free acceleration integrated from one anchor to the next, its drift
removed linearly so that it matches the known velocity at both ends and at every still sample
in between (the classic ZUPT with linear de-drifting: Skog et al. 2010, Foxlin 2005).
World frame here: z up, metres, seconds.
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import cumulative_trapezoid
from scipy.spatial.transform import Rotation

from imuloco.ops.rotations import IDENTITY, from_rotvec, normalize, qmul
from imuloco.sensors.noise import G

UP = np.array([0.0, 0.0, 1.0])


def integrate_gyro(gyro: np.ndarray, rate: float) -> Rotation:
    """Orientations (T,) of a sensor from its body-frame angular velocity (T, 3) rad/s on a
    uniform grid at ``rate`` Hz, the first the identity: ``R[i+1] = R[i] exp(w[i] / rate)``.

    scipy has no cumulative product of rotations, and one ``Rotation`` per sample costs
    ~0.6 ms: the product is a parallel prefix scan (Hillis & Steele) of vectorised
    quaternion products, log2(T) passes."""
    q = np.empty((len(gyro), 4))
    q[0] = IDENTITY
    q[1:] = from_rotvec(np.asarray(gyro[:-1], float) / rate)
    d = 1
    while d < len(q):
        q[d:] = qmul(q[:-d], q[d:])  # the right side is built from the previous pass
        d *= 2
    return Rotation.from_quat(normalize(q))


def level(orientation: Rotation, acc: np.ndarray) -> Rotation:
    """``orientation`` (sensor to world) turned about a horizontal axis, by the least angle, so
    that the specific force ``acc`` (3,) points up: its tilt reset, its yaw kept."""
    up = orientation.apply(acc / np.linalg.norm(acc))
    axis = np.cross(up, UP)
    s = np.linalg.norm(axis)
    if s < 1e-12:
        return orientation
    return Rotation.from_rotvec(axis / s * np.arctan2(s, up @ UP)) * orientation


def anchored_path(acc: np.ndarray, gyro: np.ndarray, rate: float, anchors: np.ndarray,
                  lever: np.ndarray, still: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The path of the point ``lever`` metres from the sensor (the pivot; sensor frame, from
    the pivot to the sensor) that is still at every anchor.

    acc, gyro : (T, 3) m/s^2 and rad/s in the sensor's frame, uniform grid at ``rate`` Hz.
    anchors : (K,) increasing samples where the pivot is still (mid-stances), K >= 1.
    lever : (3,) the lever arm ``r``; at an anchor the sensor moves at ``R (w x r)``.
    still : (T,) bool, samples where the whole limb is still (velocity zero), or None.

    Returns the pivot's path (T, 3) (z up, held before the first anchor and after the last),
    the sensor's orientations (T, 4) x, y, z, w, and the velocity correction (K - 1,) m/s
    each segment needed at its end (how far the integration drifted: a confidence cue).
    """
    t_n = len(acc)
    anchors = np.asarray(anchors, int)
    raw = integrate_gyro(gyro, rate)
    pivot = np.zeros((t_n, 3))
    quat = np.tile([0.0, 0.0, 0.0, 1.0], (t_n, 1))
    drift = np.zeros(max(len(anchors) - 1, 0))
    a0 = int(anchors[0])
    ori = level(Rotation.identity(), _mean_acc(acc, a0, rate))
    here = np.zeros(3)
    for k in range(len(anchors) - 1):
        a, b = int(anchors[k]), int(anchors[k + 1])
        rel = raw[a].inv() * raw[a:b + 1]  # the gyroscope's rotation since the anchor
        seg = ori * rel
        acc_w = seg.apply(acc[a:b + 1]) - G * UP
        v_a = ori.apply(np.cross(gyro[a], lever))
        v = v_a + cumulative_trapezoid(acc_w, dx=1.0 / rate, axis=0, initial=0.0)
        # the known velocities: both anchors, and the pivot's wherever the limb is still
        inner = [] if still is None else list(np.flatnonzero(still[a + 1:b]) + 1)
        idx = np.array([0, *inner, b - a], int)
        known = seg[idx].apply(np.cross(gyro[a + idx], lever))
        err = v[idx] - known
        drift[k] = float(np.linalg.norm(err[-1]))
        v -= np.stack([np.interp(np.arange(b - a + 1), idx, err[:, j]) for j in range(3)], -1)
        p = cumulative_trapezoid(v, dx=1.0 / rate, axis=0, initial=0.0)
        sensor0 = here + ori.apply(lever)
        piv = sensor0 + p - seg.apply(lever)
        piv[:, 2] -= np.linspace(0.0, piv[-1, 2] - here[2], len(piv))  # level floor at anchors
        pivot[a:b + 1] = piv
        quat[a:b + 1] = seg.as_quat()
        here = piv[-1].copy()
        ori = level(seg[-1], _mean_acc(acc, b, rate))
    first_ori = level(Rotation.identity(), _mean_acc(acc, a0, rate))
    last = int(anchors[-1])
    for lo, hi, start, ori_at, sign in ((last, t_n, last, ori, 1), (0, a0 + 1, a0, first_ori, -1)):
        if hi - lo < 2:
            continue
        seg = ori_at * (raw[start].inv() * raw[lo:hi])
        known = seg.apply(np.cross(gyro[lo:hi], lever))
        piv = _open_end(seg.apply(acc[lo:hi]) - G * UP, known,
                        np.zeros(hi - lo, bool) if still is None else still[lo:hi], rate, sign)
        piv -= seg.apply(lever) - seg[start - lo].apply(lever)  # the sensor to the pivot
        piv[:, 2] = 0.0
        pivot[lo:hi] = pivot[start] + piv - piv[start - lo]
    return pivot, quat, drift


def _open_end(acc_w: np.ndarray, known: np.ndarray, still: np.ndarray, rate: float,
              sign: int) -> np.ndarray:
    """The sensor's positions (N, 3) from the world acceleration (N, 3) integrated away from
    a known velocity at one end (the first sample for ``sign`` 1, the last for -1), reset to
    ``known`` (N, 3) at that end and at every ``still`` sample (no later anchor to de-drift
    against: the ends of a recording)."""
    if sign < 0:  # backwards in time: dv/ds = -a and dp/ds = -v for s = -t
        return -_open_end(-acc_w[::-1], known[::-1], still[::-1], rate, 1)[::-1]
    c = cumulative_trapezoid(acc_w, dx=1.0 / rate, axis=0, initial=0.0)
    reset = still.copy()
    reset[0] = True
    offset = np.where(reset[:, None], known - c, np.nan)
    idx = np.where(reset, np.arange(len(c)), 0)
    np.maximum.accumulate(idx, out=idx)
    v = c + offset[idx]
    return cumulative_trapezoid(v, dx=1.0 / rate, axis=0, initial=0.0)


def _mean_acc(acc: np.ndarray, i: int, rate: float, half_s: float = 0.025) -> np.ndarray:
    """The specific force averaged over ``half_s`` either side of sample ``i``."""
    h = max(1, round(half_s * rate))
    return acc[max(0, i - h):i + h + 1].mean(0)
