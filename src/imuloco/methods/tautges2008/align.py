"""The distance of Tautges et al. 2008 eq. 17 and the world-frame accelerations it compares.

Eq. 17 treats the acceleration vectors of all sensors and frames of a window as one point
cloud and takes the distance minimized over a rotation about the vertical (Y) axis, which has
the closed form of Kovar, Gleicher and Pighin 2002 (without the translation, which plays no
role for accelerations).
"""

from __future__ import annotations

import numpy as np

from imuloco.ops.rotations import about_y, qrot
from imuloco.sensors.fusion import madgwick
from imuloco.sensors.simulate import GRAVITY


def vertical_rotation(a: np.ndarray, b: np.ndarray, weights: np.ndarray | None = None
                      ) -> np.ndarray:
    """The angle theta that minimizes ``sum_i w_i |a_i - R_y(theta) b_i|^2``.

    a, b : ndarray, shape (..., N, 3), Y up; weights : (..., N) or None -> theta (...), rad,
    with ``R_y`` = :func:`imuloco.ops.rotations.about_y`.

    Expanding the square, only ``a . R_y b = cos(theta) (a_x b_x + a_z b_z) + sin(theta)
    (a_x b_z - a_z b_x) + a_y b_y`` depends on theta, so the maximum is at the atan2 below.
    """
    w = np.ones(a.shape[:-1]) if weights is None else weights
    s = np.sum(w * (a[..., 0] * b[..., 2] - a[..., 2] * b[..., 0]), axis=-1)
    c = np.sum(w * (a[..., 0] * b[..., 0] + a[..., 2] * b[..., 2]), axis=-1)
    return np.arctan2(s, c)


def eq17_distance(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 17 between a recorded window ``a`` and synthesized windows ``b``, with one rotation
    about the vertical per sensor (our sensors' headings are unrelated, see
    :func:`world_acceleration`).

    a : (F, S, 3), b : (..., F, S, 3) -> distance (...) (mean squared, m^2/s^4), theta (..., S).
    We minimize the sum of squared distances, for which the closed form of [KGP02] holds (the
    paper cites it for the minimization, and writes the norm unsquared).
    """
    a_s = np.moveaxis(a, -2, -3)                 # (S, F, 3)
    b_s = np.moveaxis(b, -2, -3)                 # (..., S, F, 3)
    theta = vertical_rotation(a_s, b_s)          # (..., S)
    rb = qrot(about_y(theta)[..., None, :], b_s)
    return np.mean(np.sum((a_s - rb) ** 2, axis=-1), axis=(-1, -2)), theta


def world_acceleration(signals: np.ndarray, fps: float) -> np.ndarray:
    """Free accelerations in a Y-up frame of each sensor, from its own accelerometer and gyro.

    signals : (T, 6 S) (acc x,y,z m/s^2 then gyro x,y,z rad/s per sensor) -> (T, S, 3).

    The paper's XSens sensors give their orientation in one common frame; a phone (and our
    virtual sensors) give acceleration and angular rate only. Each sensor's orientation comes
    from the shared Madgwick filter (:func:`imuloco.sensors.fusion.madgwick`): tilt is kept by
    gravity, heading is integrated from the gyro, so every sensor has its own unknown heading
    and eq. 17 is minimized over one rotation about the vertical per sensor.
    """
    t = len(signals)
    times = np.arange(t) / fps
    out = np.empty((t, signals.shape[1] // 6, 3))
    for s in range(out.shape[1]):
        acc, gyr = signals[:, 6 * s:6 * s + 3], signals[:, 6 * s + 3:6 * s + 6]
        out[:, s] = qrot(madgwick(times, acc, gyr), acc) + GRAVITY
    return out
