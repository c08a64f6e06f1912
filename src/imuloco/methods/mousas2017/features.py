"""Feature vectors of Mousas 2017 sec. 4.4: full-body x_t and sensor y_t.

``x_t = [r_t, omega_t, dtau_t]``: joint rotations, joint angular velocities and the root
displacement. Here ``r_t`` and ``dtau_t`` are the shared pose vector of
:mod:`imuloco.methods.pose` (6-D local rotations with the root's relative to the heading, root
height, horizontal root velocity in the heading frame and yaw rate: the root displacement
between frames expressed on the ground plane after removing the rotation about the vertical,
which is the decomposition of sec. 4.3), followed by ``omega_t`` (local angular velocity of
every joint, rad/s, backward difference) and the two foot contacts (left, right) that the
foot-skate clean-up needs at run time. The paper lists no contacts in x_t; they ride along as
two extra dimensions that are interpolated like the rest and never enter the likelihood.

``y_t = [e_t, omega_t]``: acceleration then angular velocity of each sensor, which is exactly
the signal row of :mod:`imuloco.methods.training` (6 per sensor).
"""

from __future__ import annotations

import numpy as np

from imuloco.core.motion import Motion
from imuloco.methods import pose
from imuloco.ops.heading import to_heading_frame
from imuloco.ops.rotations import about_y, qinv, qmul, to_rotvec


def layout(num_joints: int) -> dict[str, slice]:
    """Where each feature lives in x_t for a skeleton of ``num_joints`` joints."""
    j = num_joints
    return {
        "pose": slice(0, 6 * j + 4),        # pose.encode vector (rotations + root)
        "rot6d": slice(0, 6 * j),
        "root": slice(6 * j, 6 * j + 4),    # height, velocity (left, forward), yaw rate
        "omega": slice(6 * j + 4, 9 * j + 4),
        "contacts": slice(9 * j + 4, 9 * j + 6),
    }


def x_dim(num_joints: int) -> int:
    return 9 * num_joints + 6


def angular_velocity(motion: Motion) -> np.ndarray:
    """Local angular velocity of every joint, shape (T, J, 3), rad/s, in the joint's own frame
    (``q_t = q_{t-1} exp(omega_t / fps)``); the root's is taken relative to the heading, so it
    does not see the turning of the whole body. Backward differences, the first frame repeating
    the second."""
    theta = np.unwrap(pose.heading(motion))
    rot = motion.rotations.copy()
    rot[:, 0] = qmul(qinv(about_y(theta)), rot[:, 0])
    if motion.num_frames < 2:
        return np.zeros(rot.shape[:-1] + (3,))
    w = to_rotvec(qmul(qinv(rot[:-1]), rot[1:])) * motion.fps
    return np.concatenate([w[:1], w], axis=0)


def motion_features(motion: Motion, contacts: np.ndarray) -> np.ndarray:
    """x_t for every frame, shape (T, 9 J + 6) (see :func:`layout`).

    contacts : ndarray, shape (T, 2), left and right foot contact (0 or 1).
    """
    t = motion.num_frames
    return np.concatenate([pose.encode(motion), angular_velocity(motion).reshape(t, -1),
                           np.asarray(contacts, dtype=np.float64).reshape(t, 2)], axis=1)


def registration_features(motion: Motion) -> np.ndarray:
    """Joint positions in the heading frame at the root's ground point, shape (T, 3 J), metres:
    each pose without its translation on the ground plane and its rotation about the vertical,
    the point cloud that Kovar and Gleicher's registration (sec. 4.3) compares."""
    pos = motion.positions()
    origin = motion.root * np.array([1.0, 0.0, 1.0])
    local = to_heading_frame(pos, origin, np.unwrap(pose.heading(motion)))
    return local.reshape(motion.num_frames, -1)
