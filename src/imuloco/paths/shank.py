"""The path of a walker from a shank (shin, ankle) sensor: the pivot model.

In stance the shank pivots about the ankle, which is still from foot flat to heel off: there
the sensor moves at ``omega x r``, ``r`` the lever arm from the ankle to the sensor (the
inverted-pendulum / pivot model of shank-IMU stride estimation: e.g. Li et al. 2010, "Walking
speed and slope estimation using shank-mounted inertial measurement units"; Sci Rep 2021,
shank-based IMU with an inverted pendulum model). Between two mid-stances the sensor's
orientation is the gyroscope integrated, its tilt reset by gravity at each mid-stance, and its
velocity the gravity-free acceleration integrated from ``omega x r`` at one mid-stance to
``omega x r`` at the next (:func:`imuloco.sensors.strapdown.anchored_path`); the ankle is the
sensor's position minus ``R r``, and a stride is the ankle's displacement between successive
mid-stances.

- Swings: peaks of the gyroscope's norm above SWING_RAD_S, at least MIN_STRIDE_S apart (the
  shank swings once per stride, at 3-6 rad/s; in stance it turns at about 1 rad/s).
- Mid-stance: the stillest moment (the gyroscope norm's 50 ms maximum, least) between two
  swings, and before the first and after the last where the shank turns slower than
  STANCE_RAD_S.
- The lever arm: the shank's axis in the sensor from :func:`imuloco.sensors.calibration.
  estimate_mounting`, its length from the placement's position on the shank
  (:mod:`imuloco.sensors.placement`: 0.2 of the shank above the ankle joint, 4.5 cm in front
  of the bone) and the shank's length, SHANK_RATIO x the walker's height (``--height``,
  DEFAULT_HEIGHT_M when not given).
- The pelvis: the ankle's path averaged over one stride (:mod:`imuloco.paths.geometry`).
"""

from __future__ import annotations

from itertools import pairwise

import numpy as np
from scipy.ndimage import maximum_filter1d
from scipy.signal import find_peaks

from imuloco.core.recording import Recording
from imuloco.errors import InputError, UnknownNameError
from imuloco.ops.filters import gaussian_smooth, resample_uniform
from imuloco.ops.rotations import qinv, qrot
from imuloco.paths.base import BodyPath, strides_from_footfalls
from imuloco.paths.geometry import (
    footfalls_at,
    initial_yaw,
    pelvis_of_limb,
    rotate,
    still_path,
)
from imuloco.sensors.calibration import estimate_mounting
from imuloco.sensors.placement import get_placement
from imuloco.sensors.strapdown import anchored_path

SHANKS = ("right_ankle", "left_ankle")
SHANK_RATIO = 0.246  # shank (knee to ankle joint) over body height (Winter 2009, Fig. 4.1)
DEFAULT_HEIGHT_M = 1.70  # an adult's, when --height is not given (lever arm error ~1 cm)
RATE = 100.0  # Hz of the grid the integration runs on
SWING_RAD_S = 2.0  # a swing's peak: the shank's mid-swing rate is 3-6 rad/s walking
MIN_STRIDE_S = 0.5  # two swings of one shank are at least this far apart (sprinting ~0.6 s)
STANCE_RAD_S = 1.5  # the stillest moment of a stance: the shank turns slower than this
STILL_RAD_S = 0.2  # the whole leg still (standing): the ankle's velocity is zero
STILL_WINDOW_S = 0.05  # the ZUPT detector's window (gaitmap RtsKalman's default)
DRIFT_SCALE = 0.5  # m/s: a segment whose velocity drifted this much gets confidence 1/e
NOTE = ("shank-pivot: distance and stride lengths from the shank's strapdown integration "
        "between mid-stances (the shank pivoting about the still ankle); the heading is the "
        "gyroscope's and drifts slowly with its bias. The pelvis is the ankle's path averaged "
        "over one stride: its turns are smoothed over a stride.")


def shank_axes(rec: Recording, placement: str, height_m: float | None
               ) -> tuple[np.ndarray, np.ndarray]:
    """The lever arm (3,) from the ankle joint to the sensor, metres, and the axis (3,) the
    forward swing turns about, both in the sensor's axes (see the module docstring);
    InputError when the shank never swings (no mounting)."""
    place = get_placement(placement)
    shank = SHANK_RATIO * (height_m or DEFAULT_HEIGHT_M)
    r_segment = np.array([0.0, (1.0 - place.fraction) * shank, 0.0]) + np.asarray(place.surface)
    to_sensor = qinv(np.asarray(estimate_mounting(rec, placement).rotation))
    # the segment's x is the body's left: the forward swing turns the shank about -x
    return qrot(to_sensor, r_segment), qrot(to_sensor, np.array([-1.0, 0.0, 0.0]))


def mid_stances(gyro: np.ndarray, rate: float, swing_axis: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """The swings' peaks (K,) and the mid-stances between and around them (samples), of a
    shank's gyroscope (T, 3) rad/s at ``rate`` Hz (module docstring).

    swing_axis : (3,) unit axis in the sensor's frame about which the forward swing turns
    positively (the shank turns the other way in stance, which is how a lively stance's fast
    turning is told from a swing)."""
    sag = gaussian_smooth(gyro @ swing_axis, 0.03 * rate)
    if -np.percentile(sag, 1) > np.percentile(sag, 99):
        sag = -sag  # walking backwards: the swing's lobe is the larger one whichever way
    height = max(SWING_RAD_S, 0.4 * float(np.percentile(sag, 99)))
    peaks, _ = find_peaks(sag, height=height, distance=max(1, round(MIN_STRIDE_S * rate)),
                          prominence=1.0)
    if len(peaks) == 0:
        return peaks, np.zeros(0, int)
    energy = maximum_filter1d(np.linalg.norm(gyro, axis=1),
                              max(1, round(STILL_WINDOW_S * rate)))
    bounds = np.concatenate([[0], peaks, [len(sag)]])
    mids = []
    for lo, hi in pairwise(bounds):
        if hi - lo < 3:
            continue
        # the stance turns the shank against the swing: the middle half of its lobe of the
        # swing rate below 0 (a swing's end, where the rate changes sign, can be as still)
        against = np.flatnonzero(sag[lo:hi] < 0)
        inner = 0 < lo and hi < len(sag) and len(against) > 0
        if len(against):
            a, b = lo + int(against[0]), lo + int(against[-1]) + 1
            q = (b - a) // 4
            lo, hi = (a + q, b - q) if b - a >= 4 else (a, b)
        i = lo + int(np.argmin(energy[lo:hi]))
        # between two swings is a stance however fast (running); before the first and after
        # the last, only a stance slow enough, and not at the recording's end (a cut swing)
        edge = i <= 1 or i >= len(sag) - 2
        if inner or energy[i] < (STILL_RAD_S if edge else STANCE_RAD_S):
            mids.append(i)
    return peaks, np.asarray(mids, int)


class ShankPivot:
    """:class:`imuloco.paths.base.PathEstimator` of a shank sensor (module docstring)."""

    name = "shank-pivot"

    def estimate(self, rec: Recording, placement: str, height_m: float | None = None
                 ) -> BodyPath:
        if placement not in SHANKS:
            raise UnknownNameError(f"shank-pivot estimates a path from {SHANKS}, got "
                                   f"{placement!r}")
        k = rec.placements.index(placement)
        foot = placement.split("_")[0]
        if len(rec.times) < 2 or rec.times[-1] - rec.times[0] < 1.0:
            return still_path(rec.times, self.name, "the recording is shorter than 1 s")
        x = resample_uniform(rec.times, np.concatenate([rec.acc[:, k], rec.gyro[:, k]], 1), RATE)
        acc, gyro = x[:, :3], x[:, 3:]
        times = rec.times[0] + np.arange(len(x)) / RATE
        try:
            lever, axis = shank_axes(rec.select([placement]), placement, height_m)
        except InputError as e:
            return still_path(times, self.name, str(e))
        peaks, mids = mid_stances(gyro, RATE, axis)
        if len(peaks) == 0 or len(mids) < 2:
            return still_path(times, self.name, "the shank never swings: no walking")
        still = maximum_filter1d(np.linalg.norm(gyro, axis=1),
                                 max(1, round(STILL_WINDOW_S * RATE))) < STILL_RAD_S
        ankle, _, drift = anchored_path(acc, gyro, RATE, mids, lever, still)
        xy = ankle[:, :2] - ankle[mids[0], :2]
        xy = rotate(xy, -initial_yaw(xy[mids]))
        root, heading = pelvis_of_limb(xy, times, mids, RATE, foot)
        origin = root[0].copy()
        conf = np.exp(-np.concatenate([[0.0], drift]) / DRIFT_SCALE)
        conf = np.minimum(conf, np.concatenate([conf[1:], [1.0]]))  # a footfall ends two
        footfalls = footfalls_at(foot, times, xy - origin, mids, conf)
        return BodyPath(times, root - origin, heading, footfalls,
                        strides_from_footfalls(footfalls), self.name, NOTE, "travel")
