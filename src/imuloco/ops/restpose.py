"""Rest-pose re-expression: the same motion on joint frames that sit otherwise at rest.

A skeleton's rest pose is its pose with every local rotation the identity. A new rest pose is
given by ``rest`` (J, 4): the global rotation each joint's frame takes in it. The new joint
frames are the old ones turned by ``rest^-1`` (``F'_j = F_j rest_j^-1``), so that at the new
rest every new frame is the world's (the BVH convention), and

- the offsets become the bones' world directions there: ``o'_j = rest_p o_j``,
- the local rotations ``q'_j = rest_p q_j rest_j^-1`` (``rest_p`` the identity for the root),

which leaves every joint's world position unchanged in every frame
(``G'_j = G_j rest_j^-1`` and ``G'_p o'_j = G_p o_j``).
"""

from __future__ import annotations

import numpy as np

from imuloco.ops.rotations import IDENTITY, qinv, qmul, qrot


def parent_rest(rest: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """Each joint's parent's rest rotation (the identity for the root): (J, 4).
    rest : (J, 4) quaternions x, y, z, w; parents : (J,)."""
    rest = np.asarray(rest, dtype=np.float64)
    out = rest[np.maximum(parents, 0)].copy()
    out[np.asarray(parents) < 0] = IDENTITY
    return out


def rebase_offsets(offsets: np.ndarray, parents: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """Offsets (J, 3) in the new rest pose's frames: ``rest_p o_j``."""
    return qrot(parent_rest(rest, parents), np.asarray(offsets, dtype=np.float64))


def rebase_rotations(rotations: np.ndarray, parents: np.ndarray, rest: np.ndarray
                     ) -> np.ndarray:
    """Local rotations (..., J, 4) re-expressed on the new rest pose's frames:
    ``rest_p q_j rest_j^-1``. rotations : (..., J, 4); parents : (J,); rest : (J, 4)."""
    return qmul(qmul(parent_rest(rest, parents), rotations), qinv(rest))


def rest_globals(local_rest: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """Global rotations (J, 4) of a pose given by local rotations (J, 4) (parents precede
    children)."""
    out = np.array(local_rest, dtype=np.float64)
    for j, p in enumerate(parents):
        if p >= 0:
            out[j] = qmul(out[p], out[j])
    return out
