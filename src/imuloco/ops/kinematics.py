"""Forward kinematics, vectorised over any leading (batch, frame) dimensions."""

from __future__ import annotations

import numpy as np

from imuloco.ops.rotations import from_matrix, qrot, to_matrix


def fk(
    rotations: np.ndarray, root: np.ndarray, offsets: np.ndarray, parents: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Global joint rotations and positions.

    Parameters
    ----------
    rotations : ndarray, shape (..., J, 4), local joint rotations, quaternions x, y, z, w.
    root : ndarray, shape (..., 3), world position of joint 0 (metres).
    offsets : ndarray, shape (J, 3), each joint's position in its parent's frame.
    parents : ndarray, shape (J,), parent indices, -1 for the root, parents[j] < j.

    Returns
    -------
    global_rotations : ndarray, shape (..., J, 4)
    positions : ndarray, shape (..., J, 3)
    """
    rotations = np.asarray(rotations, dtype=np.float64)
    # Rotation matrices: one scipy conversion each way, and a matrix product per joint, cost
    # less than quaternion products (numpy call overhead dominates for a single frame).
    local = to_matrix(rotations)
    glob = np.empty_like(local)
    pos = np.empty(rotations.shape[:-1] + (3,))
    glob[..., 0, :, :] = local[..., 0, :, :]
    pos[..., 0, :] = root
    for j in range(1, len(parents)):  # the tree order is inherently sequential; J is small
        p = parents[j]
        glob[..., j, :, :] = glob[..., p, :, :] @ local[..., j, :, :]
        pos[..., j, :] = pos[..., p, :] + glob[..., p, :, :] @ offsets[j]
    return from_matrix(glob), pos


def joint_positions(rotations: np.ndarray, root: np.ndarray, offsets: np.ndarray,
                    parents: np.ndarray, joints: list[int]) -> np.ndarray:
    """World positions of a few ``joints`` only, from the chains that lead to them: cheaper
    than :func:`fk` when they are few (the readers' up-axis check).

    rotations : (..., J, 4); root : (..., 3); offsets : (J, 3); parents : (J,) -> (..., K, 3).
    """
    needed: set[int] = set()
    for j in joints:
        while j >= 0 and j not in needed:
            needed.add(j)
            j = int(parents[j])
    order = sorted(needed)  # parents before children
    local = to_matrix(np.asarray(rotations, dtype=np.float64)[..., order, :])
    glob: dict[int, np.ndarray] = {}
    pos: dict[int, np.ndarray] = {}
    for i, j in enumerate(order):
        p = int(parents[j])
        if p < 0:
            glob[j], pos[j] = local[..., i, :, :], np.asarray(root, dtype=np.float64)
        else:
            glob[j] = glob[p] @ local[..., i, :, :]
            pos[j] = pos[p] + glob[p] @ offsets[j]
    return np.stack([pos[j] for j in joints], axis=-2)


def point_on_segment(
    global_rotations: np.ndarray, positions: np.ndarray, joint: int, offset: np.ndarray
) -> np.ndarray:
    """World position of a point fixed to ``joint``'s frame at ``offset`` (J's local frame).
    global_rotations : (..., J, 4), positions : (..., J, 3) -> (..., 3)."""
    return positions[..., joint, :] + qrot(global_rotations[..., joint, :], offset)
