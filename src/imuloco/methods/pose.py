"""Pose vectors: a Motion as one row of numbers per frame, and back.

Every regression-style method predicts the same vector, so encoding and decoding live here once.
A frame's vector (``D = 6 J + 4``) holds, in order:

- ``[0:6J]`` each joint's local rotation in the 6-D representation
  (:func:`imuloco.ops.rotations.to_6d`); the root's is relative to the heading frame;
- ``[6J]`` root height above the clip's floor, metres;
- ``[6J+1 : 6J+3]`` root horizontal velocity in the heading frame (left, forward), m/s;
- ``[6J+3]`` heading (yaw) rate, rad/s.

Velocities are backward differences (frame t minus frame t-1), so that a causal method can
predict them and decoding them again is exact.

The heading comes from the hip line (:mod:`imuloco.ops.heading`). Decoding integrates the
velocities from a start position and heading.
"""

from __future__ import annotations

import numpy as np

from imuloco.core.motion import Motion
from imuloco.core.skeleton import Skeleton
from imuloco.ops.heading import heading_from_hips
from imuloco.ops.rotations import about_y, continuous, from_6d, qinv, qmul, qrot, to_6d


def heading(motion: Motion) -> np.ndarray:
    """Heading angle per frame (T,) from the hip line, radians."""
    hips = motion.part_positions(["left_hip", "right_hip"])
    return heading_from_hips(hips[:, 0], hips[:, 1])


def pose_dim(skeleton: Skeleton) -> int:
    return 6 * skeleton.num_joints + 4


def height_index(skeleton: Skeleton) -> int:
    """The column of the root's height in a pose vector."""
    return 6 * skeleton.num_joints


def encode(motion: Motion) -> np.ndarray:
    """Pose vectors (T, 6J+4) of a motion (see the module docstring)."""
    theta = np.unwrap(heading(motion))
    rot = motion.rotations.copy()
    rot[:, 0] = qmul(qinv(about_y(theta)), rot[:, 0])
    vel = _backward_diff(motion.root) * motion.fps
    vel_local = qrot(qinv(about_y(theta)), vel)
    yaw_rate = _backward_diff(theta) * motion.fps
    height = motion.root[:, 1:2]
    t = motion.num_frames
    return np.concatenate([to_6d(rot).reshape(t, -1), height, vel_local[:, [0, 2]],
                           yaw_rate[:, None]], axis=1)


def _backward_diff(x: np.ndarray) -> np.ndarray:
    """x[t] - x[t-1] along axis 0, the first row repeating the second (causal velocities)."""
    d = np.diff(x, axis=0)
    return np.concatenate([d[:1], d], axis=0) if len(d) else np.zeros_like(x)


def decode(vectors: np.ndarray, skeleton: Skeleton, fps: float,
           start: np.ndarray | None = None, start_heading: float = 0.0, name: str = "") -> Motion:
    """A Motion from pose vectors (T, 6J+4).

    The root's horizontal path integrates the predicted velocity from ``start`` (a world
    position (3,) whose x and z are used; the origin by default) and heading ``start_heading`` (radians, integrated with the yaw rate).
    """
    vectors = np.asarray(vectors, dtype=np.float64)
    t, j = len(vectors), skeleton.num_joints
    rot = from_6d(vectors[:, : 6 * j].reshape(t, j, 6))
    theta = start_heading + np.cumsum(np.r_[0.0, vectors[1:, 6 * j + 3]]) / fps
    yaw = about_y(theta)
    rot[:, 0] = qmul(yaw, rot[:, 0])
    vel = np.zeros((t, 3))
    vel[:, [0, 2]] = vectors[:, 6 * j + 1: 6 * j + 3]
    vel = qrot(yaw, vel)
    root = np.zeros((t, 3))
    root[1:, [0, 2]] = np.cumsum(vel[1:, [0, 2]], axis=0) / fps
    if start is not None:
        root[:, [0, 2]] += np.asarray(start, dtype=np.float64)[[0, 2]]
    root[:, 1] = vectors[:, height_index(skeleton)]
    return Motion(skeleton, continuous(rot, axis=0), root, fps, name)
