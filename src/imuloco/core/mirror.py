"""Left/right mirroring of a motion across the body's sagittal plane.

A mirrored motion is what the same person would do with left and right swapped: a left turn
becomes a right turn, the right ankle moves as the left one did. It doubles training data and
lets a model trained for one ankle serve the other.

Joint frames of motion-capture skeletons are rarely symmetric (the shared BVH's left leg bones
point along +x of their frames, the right ones along -x), so mirroring a joint's global rotation
``W`` is ``W' = M W N`` with ``M`` the world reflection and ``N`` a per-joint reflection between
the two sides' local frames. ``N`` is not written in any file; it is estimated from the motion
(the mean of ``W_j^T M W_k`` over frames, projected onto the orthogonal matrices) and snapped to
a signed permutation when it is within :data:`SNAP_DEG` of one, as exporters' frame conventions
are. Snapping makes :func:`mirror` an exact involution.
"""

from __future__ import annotations

import re

import numpy as np

from imuloco.core.motion import Motion
from imuloco.core.skeleton import Skeleton
from imuloco.ops.heading import heading_from_hips
from imuloco.ops.rotations import about_y, continuous, from_matrix, to_matrix

SNAP_DEG = 40.0
_SIDES = [(r"_L\b", "_R"), (r"_R\b", "_L"), (r"Left", "Right"), (r"Right", "Left"),
          (r"left", "right"), (r"right", "left"), (r"^L_", "R_"), (r"^R_", "L_"),
          (r"\.L\b", ".R"), (r"\.R\b", ".L"), (r"^l_", "r_"), (r"^r_", "l_")]


def mirror_pairs(skeleton: Skeleton) -> np.ndarray:
    """Index of each joint's mirror partner (itself on the midline), shape (J,).

    Partners come from the body map's ``left_*``/``right_*`` parts, then from name patterns
    (``_L``/``_R``, ``Left``/``Right``, ``L_``/``R_``, ...).
    """
    names = list(skeleton.names)
    swap = np.arange(len(names))
    bm = skeleton.body_map or {}
    for part, joint in bm.items():
        if part.startswith("left_") and "right_" + part[5:] in bm:
            a, b = names.index(joint), names.index(bm["right_" + part[5:]])
            swap[a], swap[b] = b, a
    for i, n in enumerate(names):
        if swap[i] != i:
            continue
        for pat, rep in _SIDES:
            other = re.sub(pat, rep, n)
            if other != n and other in names:
                swap[i] = names.index(other)
                break
    if not np.array_equal(swap[swap], np.arange(len(names))):
        raise ValueError(f"mirror_pairs: inconsistent left/right partners in {names}")
    parents = np.asarray(skeleton.parents)
    for j in range(len(names)):
        pj, pk = parents[j], parents[swap[j]]
        if (pj < 0) != (pk < 0) or (pj >= 0 and swap[pj] != pk):
            raise ValueError(f"mirror_pairs: joints {names[j]!r} and {names[swap[j]]!r} have "
                             "parents that are not mirror partners")
    return swap


def _reflection(theta: float) -> np.ndarray:
    """World reflection across the vertical plane that contains heading ``theta`` (3, 3)."""
    left = np.array([np.cos(theta), 0.0, -np.sin(theta)])  # +X at theta = 0 (facing +Z)
    return np.eye(3) - 2.0 * np.outer(left, left)


def _snap(m: np.ndarray) -> np.ndarray:
    """Nearest orthogonal matrix to ``m`` (3, 3) with its sign of determinant, replaced by the
    nearest signed permutation when that is within :data:`SNAP_DEG`."""
    u, _, vt = np.linalg.svd(m)
    o = u @ vt
    cols = np.argmax(np.abs(o), axis=1)
    if len(set(cols.tolist())) < 3:
        return o
    p = np.zeros((3, 3))
    p[np.arange(3), cols] = np.sign(o[np.arange(3), cols])
    rel = p.T @ o
    if np.linalg.det(rel) < 0:
        return o
    cos = np.clip((np.trace(rel) - 1) / 2, -1.0, 1.0)
    return p if np.degrees(np.arccos(cos)) < SNAP_DEG else o


def mirror_frames(motions: Motion | list[Motion]) -> np.ndarray:
    """The per-joint reflections ``N`` (J, 3, 3) between left and right joint frames.

    Chosen so that the mirrored motions have the same mean local rotation per joint as the
    originals (locomotion is left/right symmetric on average), parents before children; the
    root's keeps its mean orientation in the heading frame.

    motions : one Motion or several on the same skeleton.
    """
    motions = [motions] if isinstance(motions, Motion) else list(motions)
    sk = motions[0].skeleton
    swap = mirror_pairs(sk)
    parents = np.asarray(sk.parents)
    lbar = np.zeros((sk.num_joints, 3, 3))
    root_h = np.zeros((3, 3))
    count = 0
    for mo in motions:
        lm = to_matrix(mo.rotations)
        lbar += lm.sum(0)
        hips = mo.part_positions(["left_hip", "right_hip"])
        theta = heading_from_hips(hips[:, 0], hips[:, 1])
        root_h += np.einsum("tab,tbc->ac", to_matrix(about_y(-theta)), lm[:, 0])
        count += mo.num_frames
    lbar /= count
    root_h /= count
    n = np.zeros_like(lbar)
    m_h = np.diag([-1.0, 1.0, 1.0])  # the heading frame's sagittal reflection (left is +X)
    order = np.argsort([_depth(parents, j) for j in range(len(parents))], kind="stable")
    for k in order:
        if parents[k] < 0:
            n[k] = _snap(root_h.T @ m_h @ root_h)
        else:
            n[k] = _snap(lbar[swap[k]].T @ n[parents[k]] @ lbar[k])
    return n


def _depth(parents: np.ndarray, j: int) -> int:
    d = 0
    while parents[j] >= 0:
        j, d = parents[j], d + 1
    return d


def mirror(motion: Motion, frames: np.ndarray | None = None,
           plane_heading: float | None = None) -> Motion:
    """The motion mirrored across the sagittal plane, left and right joints swapped.

    Parameters
    ----------
    motion : a Motion whose skeleton has left/right partners (see :func:`mirror_pairs`).
    frames : ndarray, shape (J, 3, 3), from :func:`mirror_frames`; estimated from ``motion``
        when None (pass one estimate from a whole database to mirror many clips alike).
    plane_heading : heading (radians, :mod:`imuloco.ops.heading`) of the vertical mirror plane
        through the first frame's root; the first frame's heading from the hips by default, so
        that the mirrored person sets off the same way.

    Returns
    -------
    Motion on the same skeleton whose joint ``k`` has global rotation ``M W_k' N_k`` and, for
    a symmetric skeleton, position ``M (p_k' - o) + o``, with ``k'`` the partner of ``k``,
    ``M`` the reflection and ``o`` the first root position.
    """
    sk = motion.skeleton
    swap = mirror_pairs(sk)
    n = mirror_frames(motion) if frames is None else np.asarray(frames, dtype=np.float64)
    if plane_heading is None:
        hips = motion.part_positions(["left_hip", "right_hip"])[0]
        plane_heading = float(heading_from_hips(hips[0], hips[1]))
    m = _reflection(plane_heading)
    rot = mirror_rotations(motion.rotations, n, swap, sk.parents, m)
    origin = motion.root[0]
    root = (motion.root - origin) @ m.T + origin
    return Motion(sk, continuous(rot, axis=0), root, motion.fps, motion.name)


def mirror_rotations(rotations: np.ndarray, frames: np.ndarray, swap: np.ndarray,
                     parents: np.ndarray, reflection: np.ndarray) -> np.ndarray:
    """Local rotations of the mirrored pose: ``L'_k = N_p^T L_k' N_k`` for a joint ``k`` with
    parent ``p`` and partner ``k'``, and ``R L_0' N_0`` for the root.

    Parameters
    ----------
    rotations : ndarray, shape (..., J, 4), local rotations, quaternions x, y, z, w.
    frames : ndarray, shape (J, 3, 3), from :func:`mirror_frames`.
    swap : ndarray, shape (J,), from :func:`mirror_pairs`.
    parents : ndarray, shape (J,).
    reflection : ndarray, shape (3, 3), the world (or heading-frame) reflection ``R``.

    Returns
    -------
    ndarray, shape (..., J, 4)
    """
    parents = np.asarray(parents)
    lm = to_matrix(np.asarray(rotations, dtype=np.float64))[..., swap, :, :]
    left = frames[np.where(parents >= 0, parents, 0)].swapaxes(-1, -2)
    left[parents < 0] = reflection
    out = np.einsum("jab,...jbc,jcd->...jad", left, lm, frames)
    return from_matrix(out)
