"""Virtual sensors: what an IMU fixed to the body would read during a motion.

The sensor's world position and orientation are computed at the motion's frames by forward
kinematics, then interpolated in continuous time: a cubic spline for the position
(:class:`scipy.interpolate.CubicSpline`) and a rotation spline for the orientation
(:class:`scipy.spatial.transform.RotationSpline`). Their analytic derivatives give acceleration
and angular velocity at any instant. We chose splines over finite differences of the 30 fps
frames because a phone samples at 100 Hz at irregular instants: the splines are evaluated
exactly there, with C2-continuous acceleration and without the half-frame lag and the
aliasing that differencing coarse frames brings.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation, RotationSpline

from imuloco.core.motion import Motion
from imuloco.core.recording import Recording
from imuloco.errors import InputError
from imuloco.ops.filters import resample_linear
from imuloco.ops.rotations import continuous, from_rotvec, qinv, qmul, qrot, slerp
from imuloco.sensors.noise import (
    G,
    NoiseModel,
    corrupt,
    get_noise,
    random_misplacement,
    sample_times,
)
from imuloco.sensors.placement import Placement, anatomical_frame, get_placement
from imuloco.sensors.strap import strapped

if TYPE_CHECKING:
    from imuloco.sensors.strap import Strap

GRAVITY = np.array([0.0, -G, 0.0])  # world is Y up


Attachment = tuple[int, np.ndarray, np.ndarray]  # joint, offset (3,), rotation (4,)


def attached_trajectories(motion: Motion, attachments: list[Attachment]
                          ) -> tuple[np.ndarray, np.ndarray]:
    """World positions (T, S, 3) and sensor-to-world orientations (T, S, 4) of sensors
    rigidly attached to joints (``anatomical_frame`` results), with one forward kinematics for
    all of them: optimizers that synthesize signals many times compute the attachments once."""
    grot, pos = motion.fk()
    p = np.stack([pos[:, j] + qrot(grot[:, j], off) for j, off, _ in attachments], axis=1)
    q = np.stack([continuous(qmul(grot[:, j], rot)) for j, _, rot in attachments], axis=1)
    return p, q


def sensor_trajectory(motion: Motion, placement: str | Placement) -> tuple[np.ndarray, np.ndarray]:
    """World position (T, 3) and sensor-to-world orientation (T, 4) of a sensor at the
    motion's frames."""
    # the motion's poses settle the segment's twist in a skeleton whose rest pose is not a
    # standing pose (see anatomical_frame)
    attachment = anatomical_frame(motion.skeleton, get_placement(placement), motion.rotations[::5])
    p, q = attached_trajectories(motion, [attachment])
    return p[:, 0], q[:, 0]


def ideal_signals(motion: Motion, placement: str | Placement, times: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Noise-free specific force (N, 3), angular velocity (N, 3), both in the sensor frame,
    and orientation (N, 4), at ``times`` (N,) seconds within the motion."""
    position, orientation = sensor_trajectory(motion, placement)
    frame_t = motion.times
    acc_world = CubicSpline(frame_t, position, axis=0)(times, 2)
    rspline = RotationSpline(frame_t, Rotation.from_quat(orientation))
    q = rspline(times).as_quat()
    # RotationSpline's first derivative is the angular rate in the rotating (sensor) frame:
    # checked in tests/test_sensors.py against a spin about a tilted axis.
    omega_sensor = rspline(times, 1)
    return qrot(qinv(q), acc_world - GRAVITY), omega_sensor, q


STRAP_RATE = 400.0  # Hz of the grid a strap's filters run on, before sampling at the times


def strapped_signals(motion: Motion, placement: str | Placement, times: np.ndarray,
                     strap: Strap) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`ideal_signals` of a phone on a strap (:mod:`imuloco.sensors.strap`): the rigid
    sensor's signals on a uniform grid, through the strap, then at ``times``."""
    grid = np.arange(0.0, motion.duration + 1.0 / STRAP_RATE, 1.0 / STRAP_RATE)
    grid = grid[grid <= motion.times[-1]]
    acc, gyro, q = ideal_signals(motion, placement, grid)
    acc, gyro, roll = strapped(acc, gyro, STRAP_RATE, strap)
    q = qmul(q, from_rotvec(np.outer(roll, [0.0, 1.0, 0.0])))
    t = np.clip(times, grid[0], grid[-1])
    return resample_linear(grid, acc, t), resample_linear(grid, gyro, t), slerp(q, grid, t)


def simulate(
    motion: Motion,
    placements: Sequence[str | Placement] = ("right_ankle",),
    rate: float = 100.0,
    noise: str | NoiseModel = "clean",
    seed: int = 0,
    strap: Strap | None = None,
    stomps: Sequence[float] = (),
) -> Recording:
    """Simulate body-worn sensors during ``motion``.

    Parameters
    ----------
    placements : preset names or Placement objects, one sensor each.
    rate : nominal sampling rate in Hz (phones sample at about 100 Hz).
    noise : a preset of :mod:`imuloco.sensors.noise` or a NoiseModel.
    seed : seeds every random draw, so the same arguments give the same recording.
    strap : every sensor sits on this soft-tissue strap (:mod:`imuloco.sensors.strap`);
        None: rigidly on its segment.
    stomps : seconds at which the wearer stomps (:func:`add_stomps`), the rule that aligns
        the clocks of sensors recorded apart (:mod:`imuloco.sensors.multi`).

    Returns
    -------
    Recording with timestamps (irregular when the noise model jitters or drops samples),
    specific force, angular velocity and the true orientation of every sensor.
    """
    if motion.num_frames < 2 or not placements:
        raise InputError(f"motion {motion.name!r}: simulating sensors needs at least 2 frames "
                         f"and one placement, got {motion.num_frames} and {len(placements)}")
    model = get_noise(noise)
    rng = np.random.default_rng(seed)
    times = sample_times(motion.duration, rate, model, rng)
    accs, gyros, oris = [], [], []
    for p in placements:
        place = get_placement(p)
        if model.misalignment_deg > 0 or model.offset_m > 0:
            place = place.perturbed(*random_misplacement(model, rng))
        acc, gyro, ori = (ideal_signals(motion, place, times) if strap is None else
                          strapped_signals(motion, place, times, strap))
        acc, gyro = corrupt(acc, gyro, model, rng)
        accs.append(acc)
        gyros.append(gyro)
        oris.append(ori)
    names = [get_placement(p).name for p in placements]
    rec = Recording(times, np.stack(accs, 1), np.stack(gyros, 1), names, np.stack(oris, 1))
    return add_stomps(rec, stomps) if len(stomps) else rec


EASE_S = 1.0  # seconds over which a still start speeds up into the motion


def still_start(motion: Motion, seconds: float) -> Motion:
    """``motion`` after ``seconds`` of standing in its first pose (the lead-in before
    :func:`add_stomps`' stomps: stand still, stomp, then move), then :data:`EASE_S` seconds
    in which it speeds up from rest (its first ``EASE_S / 2`` seconds played at a speed
    rising linearly from 0 to 1: no jump of velocity)."""
    n = round(seconds * motion.fps)
    u = np.arange(round(EASE_S * motion.fps)) / motion.fps  # output seconds of the ease
    src = u * u / (2 * EASE_S) * motion.fps  # source frame: speed rises from 0 to 1
    i = np.minimum(src.astype(int), motion.num_frames - 2)
    w = (src - i)[:, None]
    rot = (1 - w[..., None]) * motion.rotations[i] + w[..., None] * motion.rotations[i + 1]
    rot /= np.linalg.norm(rot, axis=-1, keepdims=True)  # steps of a frame: nlerp is enough
    root = (1 - w) * motion.root[i] + w * motion.root[i + 1]
    rest = round(EASE_S / 2 * motion.fps)
    return Motion(motion.skeleton,
                  np.concatenate([np.repeat(motion.rotations[:1], n, 0), rot,
                                  motion.rotations[rest:]]),
                  np.concatenate([np.repeat(motion.root[:1], n, 0), root, motion.root[rest:]]),
                  motion.fps, motion.name)


STOMP_LEAD_S = 2.0  # seconds of standing before the motion, with stomps at STOMP_AT_S
STOMP_AT_S = (0.5, 1.2)
STOMP_S = 0.06  # the jolt: one half sine this long (a heel strike's is 20-50 ms)
STOMP_G = {"leg": 3.0, "other": 1.5}  # its peak, g: strongest on the legs, damped above the hip


def add_stomps(rec: Recording, at: Sequence[float]) -> Recording:
    """``rec`` with the jolt of a stomp at each time of ``at`` (seconds) added to every
    sensor's specific force: a vertical (world) half sine of :data:`STOMP_S`, peaking at
    :data:`STOMP_G` (legs and feet, else the rest of the body),
    reaching every sensor at once. A model of the event, not of a body stomping (the motion
    is not changed): enough to test the clock alignment that looks for it. Needs the true
    orientation (``rec.orientation``)."""
    if rec.orientation is None:
        raise InputError("adding stomps needs the sensors' orientation (simulate gives it)")
    dt = rec.times[:, None] - np.asarray(at, dtype=np.float64)[None, :]  # (T, K)
    ring = np.where((dt >= 0) & (dt <= STOMP_S), np.sin(np.pi * dt / STOMP_S), 0.0).sum(axis=1)
    acc = rec.acc.copy()
    for k, name in enumerate(rec.placements):
        seg = get_placement(name).segment
        peak = STOMP_G["leg" if any(w in seg for w in ("knee", "ankle", "hip", "toe"))
                       else "other"] * G
        up = np.zeros((len(ring), 3))
        up[:, 1] = peak * ring
        acc[:, k] += qrot(qinv(rec.orientation[:, k]), up)
    return Recording(rec.times, acc, rec.gyro, list(rec.placements), rec.orientation)
