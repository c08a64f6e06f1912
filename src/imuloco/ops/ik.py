"""Analytic two-bone inverse kinematics (a leg: hip, knee, ankle), vectorised over frames.

Written here because the closed form is a few lines of vector algebra on imuloco's own
skeleton arrays, where a general IK library (an iterative solver over a scene graph) would
need the skeleton converted both ways every frame.
"""

from __future__ import annotations

import numpy as np

from imuloco.ops.rotations import _cross, from_rotvec, normalize, qinv, qmul, qrot

_EPS = 1e-9


def arc(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The shortest rotation taking the directions of ``u`` to those of ``v`` (..., 3) ->
    quaternions (..., 4); identity where either is zero."""
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    w = np.linalg.norm(u, axis=-1) * np.linalg.norm(v, axis=-1) + np.sum(u * v, axis=-1)
    q = np.concatenate([_cross(u, v), w[..., None]], axis=-1)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    # opposite directions (w = 0 and no cross product): a half turn about any normal of u
    half = np.concatenate([_cross(u, _normal_seed(u)), np.zeros(u.shape[:-1] + (1,))], axis=-1)
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


def two_bone(glob: np.ndarray, pos: np.ndarray, parents: np.ndarray, chain: tuple[int, int, int],
             target: np.ndarray, local: np.ndarray) -> np.ndarray:
    """Local rotations with the chain's end (an ankle) moved to ``target``, its global
    orientation kept; each frame on its own.

    The knee bends in its own plane until the hip-to-end distance is the hip-to-target one
    (law of cosines, clamped to what the bones reach), then the hip turns the leg onto the
    target by the shortest rotation. Joints between hip and knee, or knee and end, follow
    rigidly.

    Parameters
    ----------
    glob, pos : (T, J, 4) global rotations and (T, J, 3) positions (:func:`imuloco.ops.
        kinematics.fk`).
    parents : (J,) parent indices.
    chain : joint indices of the hip, knee and end, each an ancestor of the next.
    target : (T, 3) where the end should be.
    local : (T, J, 4) local rotations; a changed copy is returned.
    """
    hip, knee, end = chain
    h, k, a = pos[:, hip], pos[:, knee], pos[:, end]
    t = np.asarray(target, dtype=np.float64)
    u, v = h - k, a - k
    la, lb = np.linalg.norm(u, axis=-1), np.linalg.norm(v, axis=-1)
    reach = np.clip(np.linalg.norm(t - h, axis=-1), np.abs(la - lb) + 1e-6, la + lb - 1e-6)
    inner = np.arccos(np.clip(np.sum(u * v, axis=-1) / np.maximum(la * lb, _EPS), -1.0, 1.0))
    wanted = np.arccos(np.clip((la ** 2 + lb ** 2 - reach ** 2) / np.maximum(2 * la * lb, _EPS),
                               -1.0, 1.0))
    # the bend axis: the knee's plane; a leg held exactly straight has none, and keeps its
    # knee (only the hip turns it; chosen per frame so that one frame at a time, as a
    # stream runs, gives what a whole recording does)
    axis = _cross(u, v)
    n = np.linalg.norm(axis, axis=-1, keepdims=True)
    straight = n[:, 0] <= 1e-6 * np.maximum(la * lb, _EPS)
    axis = axis / np.maximum(n, _EPS)
    wanted = np.where(straight, inner, wanted)
    bend = from_rotvec(axis * (wanted - inner)[:, None])      # about the knee, world frame
    a2 = k + qrot(bend, v)
    turn = arc(a2 - h, t - h)                                  # about the hip, world frame
    out = np.array(local, dtype=np.float64, copy=True)
    ph = parents[hip]
    parent_h = glob[:, ph] if ph >= 0 else np.broadcast_to([0.0, 0.0, 0.0, 1.0], turn.shape)
    out[:, hip] = qmul(qinv(parent_h), qmul(turn, glob[:, hip]))
    # below the hip everything turned by ``turn``: the knee's new global is turn bend G_k
    out[:, knee] = qmul(qinv(glob[:, parents[knee]]), qmul(bend, glob[:, knee]))
    new_parent_end = qmul(turn, qmul(bend, glob[:, parents[end]]))
    out[:, end] = qmul(qinv(new_parent_end), glob[:, end])
    return normalize(out)
