"""Retargeting maths: anatomical frames of body segments, and moving global rotations from
one rig's joint frames to another's.

Two rigs rarely agree on their joint frames (the Bandai-Namco legs run along the joints' x,
Character Creator's along y; neither rig's all-zero pose is a standing pose), so a joint's
rotation cannot be copied. What two rigs share is anatomy: a segment's long axis and which
way is forward. :func:`segment_frames` builds such a frame from joint positions; expressed in
the joint's own frame (:func:`joint_local`) it is a constant of the rig, and
:func:`transfer` moves a global rotation through it: ``G_t = G_s A_s A_t^-1``.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from imuloco.ops.rotations import from_matrix, qinv, qmul, qrot

UP = np.array([0.0, 1.0, 0.0])


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, 1e-12)


def body_axes(left_hip: np.ndarray, right_hip: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The body's up (world +Y), left (the hip line, horizontal) and forward
    (``left x up``, the heading convention of :mod:`imuloco.ops.heading`) unit vectors, each
    (..., 3), from the hip joints' positions (..., 3)."""
    left = np.asarray(left_hip, dtype=np.float64) - np.asarray(right_hip)
    left[..., 1] = 0.0
    left = _unit(left)
    up = np.broadcast_to(UP, left.shape)
    return up, left, np.cross(left, up)


def segment_frames(long_axis: np.ndarray, second: np.ndarray, fallback: np.ndarray
                   ) -> np.ndarray:
    """Rotations (..., 4) whose y axis is ``long_axis`` and whose z axis is ``second`` made
    perpendicular to it (``fallback`` where ``second`` is nearly parallel), ``x = y x z``.
    All arguments (..., 3), any length."""
    y = _unit(long_axis)
    z = second - y * np.sum(second * y, axis=-1, keepdims=True)
    alt = fallback - y * np.sum(fallback * y, axis=-1, keepdims=True)
    z = _unit(np.where(np.linalg.norm(z, axis=-1, keepdims=True) < 0.2, alt, z))
    return from_matrix(np.stack([np.cross(y, z), y, z], axis=-1))


def mean_rotation(q: np.ndarray) -> np.ndarray:
    """The chordal mean (scipy ``Rotation.mean``) over axis 0 of q (N, ..., 4) -> (..., 4)."""
    q = np.asarray(q, dtype=np.float64)
    flat = q.reshape(q.shape[0], -1, 4)
    out = np.stack([Rotation.from_quat(flat[:, k]).mean().as_quat()
                    for k in range(flat.shape[1])])
    return out.reshape(q.shape[1:])


def joint_local(global_rotations: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """Anatomical frames expressed in their joints' frames, averaged over poses:
    ``mean_t(G_t^-1 A_t)``. global_rotations, frames : (T, P, 4) -> (P, 4)."""
    return mean_rotation(qmul(qinv(global_rotations), frames))


def transfer(global_rotations: np.ndarray, source_local: np.ndarray, target_local: np.ndarray
             ) -> np.ndarray:
    """Global rotations of a target rig's joints that put its anatomical frames where the
    source's are: ``G_s A_s A_t^-1``. global_rotations : (..., P, 4); source_local,
    target_local : (P, 4), the rigs' :func:`joint_local` frames -> (..., P, 4)."""
    return qmul(qmul(global_rotations, source_local), qinv(target_local))


def assemble(parents: np.ndarray, offsets: np.ndarray, neutral: np.ndarray,
             wanted: dict[int, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Local rotations that give some joints wanted global rotations, the others their
    neutral local rotation, and the joints' positions relative to the root.

    parents : (J,); offsets : (J, 3); neutral : (J, 4) local rotations;
    wanted : joint index -> global rotations (T, 4). Returns locals (T, J, 4) and positions
    (T, J, 3) with joint 0 at the origin.
    """
    t = len(next(iter(wanted.values())))
    n = len(parents)
    local = np.broadcast_to(neutral, (t, n, 4)).copy()
    glob = np.empty((t, n, 4))
    pos = np.zeros((t, n, 3))
    for j in range(n):  # parents precede children
        p = parents[j]
        if j in wanted:
            local[:, j] = wanted[j] if p < 0 else qmul(qinv(glob[:, p]), wanted[j])
        glob[:, j] = local[:, j] if p < 0 else qmul(glob[:, p], local[:, j])
        if p >= 0:
            pos[:, j] = pos[:, p] + qrot(glob[:, p], offsets[j])
    return local, pos
