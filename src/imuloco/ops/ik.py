"""Analytic two-bone inverse kinematics (a leg: hip, knee, ankle), vectorised over frames.

Written here because the closed form is a few lines of vector algebra on imuloco's own
skeleton arrays, where a general IK library (an iterative solver over a scene graph) would
need the skeleton converted both ways every frame.
"""

from __future__ import annotations

import numpy as np

from imuloco.ops.rotations import cross, normalize, qinv, qmul, qrot

_EPS = 1e-9


def arc(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The shortest rotation taking the directions of ``u`` to those of ``v`` (..., 3) ->
    quaternions (..., 4); identity where either is zero."""
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    w = np.linalg.norm(u, axis=-1) * np.linalg.norm(v, axis=-1) + np.sum(u * v, axis=-1)
    q = np.concatenate([cross(u, v), w[..., None]], axis=-1)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    # opposite directions (w = 0 and no cross product): a half turn about any normal of u
    half = np.concatenate([cross(u, _normal_seed(u)), np.zeros(u.shape[:-1] + (1,))], axis=-1)
    q = np.where(n > _EPS, q, half)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(n > _EPS, q / np.maximum(n, _EPS), [0.0, 0.0, 0.0, 1.0])


def _normal_seed(u: np.ndarray) -> np.ndarray:
    """A vector not parallel to ``u`` (..., 3)."""
    x = np.zeros_like(u)
    x[..., 0] = 1.0
    y = np.zeros_like(u)
    y[..., 1] = 1.0
    return np.where(np.abs(u[..., :1]) < 0.9 * np.linalg.norm(u, axis=-1, keepdims=True), x, y)


def two_bone(glob: np.ndarray, pos: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The local rotations of a leg whose end (an ankle) is moved to ``target``, its global
    orientation kept; each row on its own.

    The knee bends in its own plane until the hip-to-end distance is the hip-to-target one
    (law of cosines, clamped to what the bones reach), then the hip turns the leg onto the
    target by the shortest rotation. Joints between hip and knee, or knee and end, follow
    rigidly; a leg held exactly straight has no plane and keeps its knee.

    Parameters
    ----------
    glob : (N, 6, 4) global rotations of the hip's parent, the hip, the knee's parent, the
        knee, the end's parent and the end (:func:`imuloco.ops.kinematics.fk`).
    pos : (N, 3, 3) positions of the hip, the knee and the end.
    target : (N, 3) where the end should be.

    Returns
    -------
    (N, 3, 4) new local rotations of the hip, the knee and the end.
    """
    h, k, a = pos[:, 0], pos[:, 1], pos[:, 2]
    t = np.asarray(target, dtype=np.float64)
    u, v = h - k, a - k
    la, lb = np.linalg.norm(u, axis=-1), np.linalg.norm(v, axis=-1)
    reach = np.clip(np.linalg.norm(t - h, axis=-1), np.abs(la - lb) + 1e-6, la + lb - 1e-6)
    inner = np.arccos(np.clip(np.sum(u * v, axis=-1) / np.maximum(la * lb, _EPS), -1.0, 1.0))
    wanted = np.arccos(np.clip((la ** 2 + lb ** 2 - reach ** 2) / np.maximum(2 * la * lb, _EPS),
                               -1.0, 1.0))
    axis = cross(u, v)
    n = np.linalg.norm(axis, axis=-1, keepdims=True)
    straight = n[:, 0] <= 1e-6 * np.maximum(la * lb, _EPS)
    half = 0.5 * np.where(straight, 0.0, wanted - inner)
    # about the knee, world frame: the axis-angle quaternion (a formula, cheaper per call
    # than a scipy Rotation for the one frame a stream bends)
    bend = np.concatenate([axis / np.maximum(n, _EPS) * np.sin(half)[:, None],
                           np.cos(half)[:, None]], axis=-1)
    turn = arc(k + qrot(bend, v) - h, t - h)                  # about the hip, world frame
    g_ph, g_h, g_pk, g_k, g_pe, g_e = (glob[:, i] for i in range(6))
    # below the hip everything turned by ``turn``, below the knee by ``turn bend`` too
    return normalize(np.stack([qmul(qinv(g_ph), qmul(turn, g_h)),
                               qmul(qinv(g_pk), qmul(bend, g_k)),
                               qmul(qinv(qmul(turn, qmul(bend, g_pe))), g_e)], axis=1))
