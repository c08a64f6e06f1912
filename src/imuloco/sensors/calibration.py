"""Sensor-to-segment calibration: how the user strapped the phone, from the recording itself.

A phone strapped on the shank (or thigh) in any orientation is turned into the segment's
anatomical frame of :mod:`imuloco.sensors.placement` (x left, y up the segment, z forward):

* **x, medio-lateral**: the leg swings in the sagittal plane, so the shank's angular velocity
  is mostly about the medio-lateral axis: x is the principal axis of the gyroscope samples
  (first right singular vector, uncentred: rotation about a fixed axis has a non-zero mean),
  after removing the component along the up estimate (turning adds yaw about the vertical).
* **sign of x**: the largest angular velocity of a walking leg is the forward swing (mid-swing,
  4-7 rad/s on the shank against 2-4 rad/s of the stance's forward roll; Aminian et al. 2002,
  Gait Posture 15:2), and the swing is the shorter part of the cycle (~40 %). Swinging forward
  turns the segment's distal end forward, a negative rotation about +x (left). So x is signed
  to make the rate about it negative in its larger lobe, by a majority of three cues: 1st
  against 99th percentile, skewness, and time spent negative under half. On the sample
  (16 clips, phone noise) the cues agree with the truth on every shank clip and on 13-15 of
  16 thigh clips (the thigh's extension in stance is nearly as fast as its swing).
* **y, up the segment**: gravity while standing still, when the recording has at least
  ``min_still_s`` of stillness (gyro below 0.1 rad/s and specific force within 0.5 m/s^2 of g
  over 0.5 s windows). Otherwise the average specific force over the walk (linear
  accelerations average out over strides), which points along the segment's *mean walking
  inclination*, not along it: it is turned back about x by that inclination, a prior measured
  on the bundled sample's 12 walking clips with clean virtual sensors
  (:data:`WALK_INCLINATION`: shank 21.2 +- 4.7 deg forward, thigh -9.6 +- 1.0 deg; running
  gives 32 and -12). Without the prior the error would be those ~20 degrees; with it, the
  clip-to-clip spread remains. At the mid-swing peaks (Perry's tibia vertical) the shank was
  not vertical in the sample (19 +- 8 deg), so they are not used.
* **z = x cross y**, and x is re-orthogonalised as y cross z.

A sensor on the shoe (``right_foot``, ``left_foot``; anatomical frame x left, y along the foot
back to the heel, z up off the instep) is found from how the foot walks
(:func:`imuloco.sensors.foottrack.foot_track`, gaitmap): gravity while the foot rests gives
up, the strides' direction seen from the resting foot gives forward, and left is their cross
product. The virtual foot sensor lies along the foot's bones, which slope down to the toes
while the foot is flat: at rest its y and z are turned about x by that slope,
:data:`FOOT_REST_INCLINATION` (39.6 +- 2.2 deg on the bundled sample's 24 walking foot sensors,
clean virtual sensors, the median), which the calibration puts back. The foot's toe-out angle
(its axis against the walking direction, a few degrees) is left in.

A sensor at the lower back (``lower_back``, L5; anatomical frame x left, y up the trunk,
z forward) is turned by the body's axes (:func:`body_axes`): up from gravity (the mean specific
force), forward along the trunk's fore-aft sway, signed by the inverted pendulum of walking.
The virtual L5 sensor follows the pelvis, whose y leans back from the vertical while walking:
:data:`BACK_WALK_INCLINATION` (4.2 +- 1.6 deg, the median on the bundled sample's 12 walking
clips, clean virtual sensors), which the calibration puts back. Left in: the pelvis's roll
(1.5 +- 0.7 deg to the right) and its yaw against the sway's fore-aft line (4.5 +- 8.9 deg). The
pendulum's sign holds for walking only: running (a spring, slowest at the bottom) turns
forward backwards (all four running clips of the sample), so a lower-back sensor is calibrated
on walking.

Shank, thigh, foot and lower-back placements are calibrated: a placement's ``mounting``
(:data:`imuloco.sensors.placement.PRESETS`) names its routine in :data:`MOUNTINGS`. A
recording rotated as a whole gives the same result rotated, so calibrating a phone strapped in
any orientation yields the signals of one strapped in the anatomical frame.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import uniform_filter1d
from scipy.signal import butter, find_peaks, sosfiltfilt
from scipy.stats import skew

from imuloco.core.recording import Recording
from imuloco.errors import InputError
from imuloco.ops.filters import gaussian_smooth, resample_linear
from imuloco.ops.rotations import from_matrix, qinv, qmul, qrot
from imuloco.sensors.foottrack import NoWalking, foot_track
from imuloco.sensors.noise import G
from imuloco.sensors.placement import PRESETS

log = logging.getLogger(__name__)

# Mean forward inclination (degrees) of the segment's y axis while walking, from the average
# specific force of clean virtual sensors on the bundled sample's walking clips (see module
# docstring): the angle that average sits behind the segment's long axis.
WALK_INCLINATION = {"shank": 21.2, "thigh": -9.6}
# Slope (degrees) of the virtual foot sensor's y axis above the floor while the foot rests flat
# (see module docstring): measured on the bundled sample's walking clips, both feet, with
# imuloco's own foot track on clean virtual sensors.
FOOT_REST_INCLINATION = 39.6
# Backward lean (degrees) of the virtual L5 sensor's y from the vertical while walking (see
# module docstring): the mean specific force of clean virtual sensors on the bundled sample's
# 12 walking clips (walk, walk-turn-left, walk-turn-right), the median.
BACK_WALK_INCLINATION = 4.2
# Walking's step band: cadence 60-180 steps/min
STEP_BAND_HZ = (0.5, 3.0)


@dataclass(frozen=True)
class Mounting:
    """A calibration result.

    Attributes
    ----------
    rotation : ndarray, shape (4,), quaternion x, y, z, w from the phone's axes to the
        segment's anatomical frame (``acc_segment = qrot(rotation, acc_phone)``).
    up_source : ``"still"`` (gravity at rest), ``"walk"`` (mean over the walk), for a
        foot ``"stances"`` (gravity while the foot rests), for the lower back ``"mean"`` (the
        mean specific force of the whole recording).
    still_s : seconds of stillness found (0 for a foot and the lower back).
    swings : number of mid-swing peaks (strides of this leg) found; for the lower back, half
        the steps (the trunk's vertical bounces) found.
    axis_ratio : second over first singular value of the gyroscope (0: a perfect hinge; NaN
        for a foot or the lower back, whose frame does not come from it).
    """

    rotation: np.ndarray
    up_source: str
    still_s: float
    swings: int
    axis_ratio: float


def _uniform(times: np.ndarray, x: np.ndarray, rate: float = 100.0
             ) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(times[0], times[-1], 1.0 / rate)
    return t, resample_linear(times, x, t)


def still_mask(acc: np.ndarray, gyro: np.ndarray, rate: float, window_s: float = 0.5,
               gyro_tol: float = 0.1, acc_tol: float = 0.5) -> np.ndarray:
    """Samples inside windows of ``window_s`` where the sensor is at rest.

    acc, gyro : ndarray, shape (T, 3), m/s^2 and rad/s on a uniform grid at ``rate`` Hz.
    Returns a boolean mask (T,).
    """
    n = max(1, round(window_s * rate))
    ok = ((np.linalg.norm(gyro, axis=-1) < gyro_tol)
          & (np.abs(np.linalg.norm(acc, axis=-1) - G) < acc_tol)).astype(float)
    full = uniform_filter1d(ok, n, mode="constant") > 1 - 1e-9  # whole window at rest
    # every sample covered by such a window
    return uniform_filter1d(full.astype(float), n, mode="constant") > 1e-9


def estimate_mounting(rec: Recording, placement: str | int | None = None,
                      min_still_s: float = 1.0) -> Mounting:
    """Rotation from the phone's axes to the segment's anatomical frame (module docstring).

    Parameters
    ----------
    rec : a recording in m/s^2 and rad/s (any sampling; resampled internally to 100 Hz).
    placement : which sensor of ``rec`` (name or index); the only one when ``None``.
    min_still_s : seconds of stillness needed to take gravity at rest as the up axis.
    """
    if placement is None:
        if len(rec.placements) != 1:
            raise InputError(f"recording has sensors {rec.placements}: name one")
        k = 0
    else:
        k = placement if isinstance(placement, int) else rec.placements.index(placement)
    name = rec.placements[k]
    mounting = mounting_of(name)
    if mounting is None:
        calibrated = [n for n in PRESETS if mounting_of(n)]
        legs = ", ".join(n for n in calibrated if PRESETS[n].side)
        trunk = " or ".join(repr(n) for n in calibrated if not PRESETS[n].side)
        raise InputError(f"calibration needs a leg placement ({legs}) or {trunk}, got {name!r}: "
                         "the swing of the leg or the trunk's sway defines the axes")
    return MOUNTINGS[mounting](rec, k, min_still_s)


def _leg_mounting(rec: Recording, k: int, min_still_s: float) -> Mounting:
    """Rotation from a shank or thigh sensor's axes to the segment's anatomical frame, from
    the leg's swing and gravity (module docstring)."""
    name = rec.placements[k]
    rate = 100.0
    _, acc = _uniform(rec.times, rec.acc[:, k], rate)
    _, gyro = _uniform(rec.times, rec.gyro[:, k], rate)
    if len(acc) < rate:
        raise InputError("calibration needs at least 1 s of recording")
    still = still_mask(acc, gyro, rate)
    still_s = float(np.count_nonzero(still) / rate)
    # first guess of up: the average specific force (gravity up to the walk's mean inclination)
    up = acc[still].mean(0) if still_s >= min_still_s else acc.mean(0)
    up /= np.linalg.norm(up)
    # medio-lateral axis: principal axis of the gyroscope, off the up axis
    moving = ~still
    if np.count_nonzero(moving) < 3:
        raise InputError(f"{name}: the phone never moves in this recording; calibration needs "
                         "the leg to swing (walk a few steps)")
    w = gyro[moving] - np.outer(gyro[moving] @ up, up)
    _, sv, vt = np.linalg.svd(w, full_matrices=False)
    x = vt[0]
    wx = gaussian_smooth(gyro @ x, 0.02 * rate)
    # the forward swing is the larger, skewed, shorter lobe: majority of three cues
    votes = (-np.percentile(wx, 1) > np.percentile(wx, 99), skew(wx) < 0, np.mean(wx < 0) < 0.5)
    if sum(votes) < 2:
        x, wx = -x, -wx
    peaks, _ = find_peaks(-wx, height=max(0.5 * -np.percentile(wx, 1), 1.0),
                          distance=int(0.5 * rate))  # mid-swing, one per stride
    if still_s >= min_still_s:
        source, y = "still", up
    else:
        source = "walk"
        if len(peaks) < 2:
            log.warning("%s: neither standing still nor walking (%d leg swings): the mounting "
                        "is unreliable", name, len(peaks))
        a = np.deg2rad(WALK_INCLINATION[PRESETS[name].mounting])
        # turn the mean specific force forward about x by the mean inclination (Rodrigues)
        y = up * np.cos(a) + np.cross(x, up) * np.sin(a) + x * (x @ up) * (1 - np.cos(a))
    y = y - x * (y @ x)
    y /= np.linalg.norm(y)
    z = np.cross(x, y)
    x = np.cross(y, z)
    rot = from_matrix(np.stack([x, y, z], axis=0))  # rows: segment axes in phone coordinates
    return Mounting(rot, source, still_s, len(peaks), float(sv[1] / sv[0]))


def _foot_mounting(rec: Recording, k: int, min_still_s: float = 1.0) -> Mounting:
    """Rotation from a shoe sensor's axes to the foot's anatomical frame (module docstring)."""
    name = rec.placements[k]
    try:
        track = foot_track(rec.times, rec.acc[:, k], rec.gyro[:, k])
    except NoWalking as e:
        raise InputError(f"{name}: a foot sensor is calibrated from walking, and {e}") from None
    a = np.deg2rad(FOOT_REST_INCLINATION)
    # rows: the anatomical axes in the level frame (x forward, y left, z up)
    level_to_foot = from_matrix(np.array([[0.0, 1.0, 0.0],
                                          [-np.cos(a), 0.0, np.sin(a)],
                                          [np.sin(a), 0.0, np.cos(a)]]))
    return Mounting(qmul(level_to_foot, track.rotation), "stances", 0.0, len(track.starts),
                    float("nan"))


def step_band(x: np.ndarray, rate: float) -> np.ndarray:
    """``x`` (T, ...) sampled at ``rate`` Hz, band-passed along time to walking's step band
    (:data:`STEP_BAND_HZ`; 4th-order Butterworth, zero phase)."""
    band = butter(4, [STEP_BAND_HZ[0], min(STEP_BAND_HZ[1], 0.45 * rate)], "bandpass",
                  fs=rate, output="sos")
    return sosfiltfilt(band, x, axis=0)


def body_axes(acc: np.ndarray, rate: float) -> np.ndarray:
    """Rows: Mobilise-D's body axes (up, medio-lateral, forward) in sensor axes, found from the
    signal of a walking trunk alone so that the sensor may be worn in any axes.

    acc : ndarray, shape (T, 3), m/s² (+9.81 up at rest), sampled at ``rate`` Hz.

    Up is the mean acceleration's direction (gravity). The fore-aft line is the principal
    direction of the horizontal acceleration: walking shakes the trunk more fore-aft than
    sideways. Forward is the direction along it whose acceleration runs against the vertical
    velocity: over each stance the body vaults over its leg as an inverted pendulum, slowing
    while it rises and speeding up while it falls (Cavagna et al. 1977, J Physiol 268:467),
    compared in walking's step band (:func:`step_band`). Running is a spring, not a pendulum:
    there forward comes out backwards. The medio-lateral axis completes the right-handed frame
    of Mobilise-D's sensor (x up, z forward: y = z x x, to the right).
    """
    up = acc.mean(axis=0)
    up = up / np.linalg.norm(up)
    h = acc - np.outer(acc @ up, up)
    _, _, vt = np.linalg.svd(h - h.mean(axis=0), full_matrices=False)
    pa = vt[0] - up * (vt[0] @ up)
    pa /= np.linalg.norm(pa)
    vertical = step_band(acc @ up, rate)
    speed_up = step_band(np.cumsum(vertical) / rate, rate)
    if np.dot(step_band(acc @ pa, rate), speed_up) > 0:
        pa = -pa
    return np.stack([up, np.cross(pa, up), pa])


def _back_mounting(rec: Recording, k: int, min_still_s: float = 1.0) -> Mounting:
    """Rotation from a lower-back sensor's axes to the virtual L5 sensor's frame (module
    docstring)."""
    name, rate = rec.placements[k], 100.0
    _, acc = _uniform(rec.times, rec.acc[:, k], rate)
    if len(acc) < 3 * rate:
        raise InputError(f"{name}: a lower-back sensor is calibrated from walking, and the "
                         "recording is shorter than 3 s")
    up, right, forward = body_axes(acc, rate)
    # steps: the trunk's bounces, at most 3 a second, of at least 0.5 m/s² (a walking trunk's
    # vertical acceleration swings by 1-3 m/s²; a resting sensor's noise by hundredths)
    steps, _ = find_peaks(step_band(acc @ up, rate), height=0.5, distance=int(rate / 3))
    if len(steps) < 4:
        log.warning("%s: %d steps found: forward comes from walking, so the mounting is "
                    "unreliable", name, len(steps))
    a = np.deg2rad(BACK_WALK_INCLINATION)
    # rows: the sensor's axes (x left, y up the trunk, z forward) in the level frame (left, up,
    # forward): y leans back by the inclination
    level_to_back = np.array([[1.0, 0.0, 0.0],
                              [0.0, np.cos(a), -np.sin(a)],
                              [0.0, np.sin(a), np.cos(a)]])
    rows = level_to_back @ np.stack([-right, up, forward])  # in the sensor's axes
    return Mounting(from_matrix(rows), "mean", 0.0, len(steps) // 2, float("nan"))


# the routines a placement's ``mounting`` names (imuloco.sensors.placement.PRESETS), each
# (recording, sensor index, min_still_s) -> Mounting
MOUNTINGS = {"shank": _leg_mounting, "thigh": _leg_mounting, "foot": _foot_mounting,
             "lower_back": _back_mounting}


def mounting_of(name: str) -> str | None:
    """The mounting routine (:data:`MOUNTINGS`) of the placement ``name`` declares, None for
    a placement not calibrated (or a name of no preset)."""
    p = PRESETS.get(name)
    return None if p is None else p.mounting


def calibrate(rec: Recording, min_still_s: float = 1.0) -> tuple[Recording, list[Mounting]]:
    """Rotate every leg or lower-back sensor of ``rec`` into its segment's anatomical frame.

    Other sensors are left as they are (and logged). The orientation, when present, becomes
    segment-to-world: ``q_segment = q_phone * qinv(rotation)``.

    Returns
    -------
    The calibrated recording and one :class:`Mounting` per sensor (identity where skipped).
    """
    acc, gyro = rec.acc.copy(), rec.gyro.copy()
    ori = None if rec.orientation is None else rec.orientation.copy()
    mounts = []
    for k, name in enumerate(rec.placements):
        if mounting_of(name) is None:
            log.info("%s: neither a leg nor the lower back, left uncalibrated", name)
            mounts.append(Mounting(np.array([0.0, 0.0, 0.0, 1.0]), "none", 0.0, 0, np.nan))
            continue
        m = estimate_mounting(rec, k, min_still_s)
        acc[:, k] = qrot(m.rotation, acc[:, k])
        gyro[:, k] = qrot(m.rotation, gyro[:, k])
        if ori is not None:
            ori[:, k] = qmul(ori[:, k], qinv(m.rotation))
        mounts.append(m)
    return Recording(rec.times, acc, gyro, list(rec.placements), ori), mounts
