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
    # Rotation matrices: one scipy conversion each way, and a matrix product per joint, cost
    # less than quaternion products (numpy call overhead dominates for a single frame).
    glob, pos = fk_matrices(to_matrix(np.asarray(rotations, dtype=np.float64)), root, offsets,
                            parents)
    return from_matrix(glob), pos


def fk_matrices(local: np.ndarray, root: np.ndarray, offsets: np.ndarray, parents: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`fk` of local rotation matrices (..., J, 3, 3): global rotation matrices
    (..., J, 3, 3) and positions (..., J, 3). The tree is walked a level at a time (all joints
    of a depth in one product, :func:`_chains`): a few numpy calls per level rather than per
    joint, what a stream's step of several poses is made of."""
    order, levels, picks = _chains(np.asarray(parents, dtype=np.int64).tobytes(),
                                   tuple(range(len(parents))))
    local = local[..., order, :, :]
    offsets = np.asarray(offsets, dtype=np.float64)[order][..., None]  # (J, 3, 1)
    glob = np.empty_like(local)
    pos = np.empty(local.shape[:-2] + (3,))
    glob[..., 0, :, :] = local[..., 0, :, :]
    pos[..., 0, :] = root
    for here, up in levels:  # the tree order is inherently sequential, a level at a time
        above = glob[..., up, :, :]
        glob[..., here, :, :] = above @ local[..., here, :, :]
        pos[..., here, :] = pos[..., up, :] + (above @ offsets[here])[..., 0]
    return glob[..., picks, :, :], pos[..., picks, :]


def joint_positions(rotations: np.ndarray, root: np.ndarray, offsets: np.ndarray,
                    parents: np.ndarray, joints: list[int]) -> np.ndarray:
    """World positions of a few ``joints`` only, from the chains that lead to them: cheaper
    than :func:`fk` when they are few (the readers' up-axis and floor checks). The chains'
    joints are taken a tree level at a time: one product of 4x4 rigid transforms (rotation and
    offset) for all joints at a depth.

    rotations : (..., J, 4); root : (..., 3); offsets : (J, 3); parents : (J,) -> (..., K, 3).
    """
    order, levels, picks = _chains(np.asarray(parents, dtype=np.int64).tobytes(), tuple(joints))
    q = np.asarray(rotations, dtype=np.float64)[..., order, :]  # (..., N, 4)
    # each joint's transform, local then world. A few rotations: the rotation matrix of a unit
    # quaternion is linear in its products q_i q_j, one matrix product for all (scipy's
    # to_matrix builds a Rotation object a call, several times this arithmetic for a clip's
    # 16 frames); many: scipy's conversion, faster than the products' table then.
    if q.size < 4 * _FEW_ROTATIONS:
        pose = ((q[..., :, None] * q[..., None, :]).reshape(q.shape[:-1] + (16,)) @ _QQ_TO_POSE
                + _IDENTITY_POSE).reshape(q.shape[:-1] + (4, 4))
    else:
        pose = np.zeros(q.shape[:-1] + (4, 4))
        pose[..., :3, :3] = to_matrix(q)
        pose[..., 3, 3] = 1.0
    pose[..., :3, 3] = np.asarray(offsets, dtype=np.float64)[order]
    pose[..., 0, :3, 3] = root
    for here, up in levels:
        pose[..., here, :, :] = pose[..., up, :, :] @ pose[..., here, :, :]
    return pose[..., :3, 3][..., picks, :]


def _quaternion_to_pose() -> np.ndarray:
    """(16, 16): the entries of a unit quaternion's (x, y, z, w) 4x4 rotation (row-major) less
    the identity's, from the products q_i q_j (index 4 i + j): R = I + 2 (...)."""
    m = np.zeros((16, 16))
    x, y, z, w = range(4)
    entries = {(0, 0): [(-2, y, y), (-2, z, z)], (0, 1): [(2, x, y), (-2, w, z)],
               (0, 2): [(2, x, z), (2, w, y)], (1, 0): [(2, x, y), (2, w, z)],
               (1, 1): [(-2, x, x), (-2, z, z)], (1, 2): [(2, y, z), (-2, w, x)],
               (2, 0): [(2, x, z), (-2, w, y)], (2, 1): [(2, y, z), (2, w, x)],
               (2, 2): [(-2, x, x), (-2, y, y)]}
    for (r, c), terms in entries.items():
        for k, i, j in terms:
            m[4 * i + j, 4 * r + c] = k
    return m


_QQ_TO_POSE = _quaternion_to_pose()
_IDENTITY_POSE = np.eye(4).ravel()
_FEW_ROTATIONS = 1024  # below, the products' table beats scipy's conversion (measured)


def _run(index: list[int]) -> np.ndarray | slice:
    """``index`` as a slice when it is a run of consecutive numbers, or one number repeated
    (a slice of one, which broadcasts): cheaper to index by than an index array."""
    first = index[0]
    if len(set(index)) == 1:
        return slice(first, first + 1)
    if index == list(range(first, first + len(index))):
        return slice(first, first + len(index))
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
