"""Device orientation from accelerometer and gyroscope, as a phone's sensor fusion reports it.

Uses the Madgwick filter (Madgwick, Harrison and Vaidyanathan 2011, "Estimation of IMU and MARG
orientation using a gradient descent algorithm", ICORR) of the maintained ``ahrs`` package
(optional dependency: ``pip install imuloco[fusion]``), fed sample by sample with each sample's
own time step, since phone timestamps are irregular.

Without a magnetometer the heading is unobservable: the returned orientations are
sensor-to-world with world Y up (as everywhere in imuloco) and an arbitrary, slowly drifting
yaw; tilt (the direction of gravity) is what they determine.
"""

from __future__ import annotations

import numpy as np

from imuloco.core.recording import Recording
from imuloco.ops.rotations import continuous, qmul

# ahrs' earth frame has z up; imuloco's world has y up: a quarter turn about x maps one to the
# other (earth z -> world y, earth y -> world -z).
_EARTH_TO_WORLD = np.array([-np.sin(np.pi / 4), 0.0, 0.0, np.cos(np.pi / 4)])


def madgwick(times: np.ndarray, acc: np.ndarray, gyro: np.ndarray, gain: float = 0.1
             ) -> np.ndarray:
    """Orientation of one sensor by the Madgwick filter.

    Parameters
    ----------
    times : ndarray, shape (T,), seconds, increasing.
    acc : ndarray, shape (T, 3), specific force in the sensor frame, m/s^2.
    gyro : ndarray, shape (T, 3), angular velocity in the sensor frame, rad/s.
    gain : the filter's beta, rad/s (sec. 3.4 of the paper). ahrs' default 0.033 needs ~15 s
        to correct a 30 degree start error; 0.1 converges within the first steps of a walk and
        keeps the tilt within a few degrees on the sample (tests/test_calibration.py).

    Returns
    -------
    ndarray, shape (T, 4), sensor-to-world quaternions x, y, z, w (world Y up, yaw arbitrary).
    """
    try:  # the [fusion] extra's
        from ahrs.common.orientation import acc2q
        from ahrs.filters import Madgwick
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("device orientation needs the 'ahrs' package: "
                          "pip install 'imuloco[fusion]'") from exc
    filt = Madgwick(gain=gain)
    dt = np.diff(times, prepend=times[0])
    q = np.empty((len(times), 4))  # ahrs order w, x, y, z; sensor -> earth
    # start from the mean specific force of the first half second (less disturbed than one)
    q[0] = acc2q(np.mean(acc[times <= times[0] + 0.5], axis=0))
    for i in range(1, len(times)):
        q[i] = filt.updateIMU(q[i - 1], gyro[i], acc[i], dt=float(dt[i]))
    xyzw = np.concatenate([q[:, 1:], q[:, :1]], axis=-1)
    return continuous(qmul(_EARTH_TO_WORLD, xyzw))


def with_orientation(rec: Recording, gain: float = 0.1) -> Recording:
    """``rec`` with ``orientation`` (T, S, 4) filled in by :func:`madgwick` for every sensor."""
    ori = np.stack([madgwick(rec.times, rec.acc[:, k], rec.gyro[:, k], gain)
                    for k in range(len(rec.placements))], axis=1)
    return Recording(rec.times, rec.acc, rec.gyro, list(rec.placements), ori)
