"""Forward kinematics, vectorised over any leading (batch, frame) dimensions."""

from __future__ import annotations

import functools

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
    than :func:`fk` when they are few (the readers' up-axis and floor checks). The chains'
    joints are taken a tree level at a time: one product of 4x4 rigid transforms (rotation and
    offset) for all joints at a depth.

    rotations : (..., J, 4); root : (..., 3); offsets : (J, 3); parents : (J,) -> (..., K, 3).
    """
    order, levels, picks = _chains(np.asarray(parents, dtype=np.int64).tobytes(), tuple(joints))
    local = to_matrix(np.asarray(rotations, dtype=np.float64)[..., order, :])  # (..., N, 3, 3)
    pose = np.zeros(local.shape[:-2] + (4, 4))  # each joint's transform, local then world
    pose[..., :3, :3] = local
    pose[..., :3, 3] = np.asarray(offsets, dtype=np.float64)[order]
    pose[..., 0, :3, 3] = root
    pose[..., 3, 3] = 1.0
    for here, up in levels:
        pose[..., here, :, :] = pose[..., up, :, :] @ pose[..., here, :, :]
    return pose[..., :3, 3][..., picks, :]


def _run(index: list[int]) -> np.ndarray | slice:
    """``index`` as a slice when it is a run of consecutive numbers, or one number repeated
    (a slice of one, which broadcasts): cheaper to index by than an index array."""
    if index == list(range(index[0], index[0] + len(index))) or len(set(index)) == 1:
        return slice(index[0], index[0] + (1 if len(set(index)) == 1 else len(index)))
    return np.array(index)


@functools.lru_cache(maxsize=64)
def _chains(parents: bytes, joints: tuple[int, ...]
            ) -> tuple[np.ndarray, list[tuple[slice, np.ndarray | slice]], np.ndarray]:
    """For :func:`joint_positions` on the tree ``parents`` (int64 bytes): the joints on the
    chains from the root to ``joints``, by depth (the root first, each tree level a run), each
    level below the root as (its run, its joints' parents) by index into them, and the index of
    each of ``joints``. Memoised: a folder's clips share one rig."""
    up = np.frombuffer(parents, dtype=np.int64)
    needed: set[int] = set()
    for j in joints:
        while j >= 0 and j not in needed:
            needed.add(j)
            j = int(up[j])
    depth: dict[int, int] = {}
    for j in sorted(needed):  # parents come first
        depth[j] = depth[int(up[j])] + 1 if up[j] >= 0 else 0
    order = sorted(needed, key=lambda j: (depth[j], j))
    slot = {j: i for i, j in enumerate(order)}
    levels = []
    for level in range(1, max(depth.values(), default=0) + 1):
        here = [slot[j] for j in order if depth[j] == level]
        levels.append((_run(here), _run([slot[int(up[order[i]])] for i in here])))
    return np.array(order, dtype=np.int64), levels, np.array([slot[j] for j in joints])


def point_on_segment(
    global_rotations: np.ndarray, positions: np.ndarray, joint: int, offset: np.ndarray
) -> np.ndarray:
    """World position of a point fixed to ``joint``'s frame at ``offset`` (J's local frame).
    global_rotations : (..., J, 4), positions : (..., J, 3) -> (..., 3)."""
    return positions[..., joint, :] + qrot(global_rotations[..., joint, :], offset)
