"""The vertical axis of a motion file: detected from the animated body, converted to Y up.

imuloco's motions are Y up (see ``docs/glossary.md``). Some exporters (3ds Max, Blender with its
default axes, MotionBuilder in Z-up scenes) write Z up. What matters is the world frame the
animation ends up in, not the rig's rest pose: the Character Creator rig of ``cmu-iclone`` has
Z-up rest offsets but a root rotated by -90 degrees about X in every frame, so its animated body
is Y up already. Detection therefore looks at the animated body: over up to 16 frames spread
over the clip, the median of the vector from the ankles (else knees) up to the head (else neck,
chest); the axis, Y or Z, along which it points up the most is up. A rig whose head and legs the
body map cannot find (see :mod:`imuloco.core.bodymap`) is taken as Y up: pass ``up="z"``.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from imuloco.core.motion import Motion
from imuloco.core.skeleton import Skeleton
from imuloco.errors import FormatError
from imuloco.ops.kinematics import joint_positions
from imuloco.ops.rotations import qinv, qmul, qrot

UP_AXES = ("auto", "y", "z")
# Z up -> Y up: the rotation by -90 degrees about X, (x, y, z) -> (x, z, -y); quaternion x,y,z,w.
Z_TO_Y = np.array([-np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)])
_DETECT_FRAMES = 16


def check_up(up: str) -> str:
    """``up`` in lower case when it is one of :data:`UP_AXES`, else a ValueError."""
    if not isinstance(up, str) or up.lower() not in UP_AXES:
        raise ValueError(f"up must be one of {list(UP_AXES)}, got {up!r}")
    return up.lower()


def spread_frames(motion: Motion, n: int) -> Motion:
    """At most ``n`` frames of ``motion``, evenly spread over it (for cheap checks)."""
    idx = spread_index(motion.num_frames, n)
    return Motion(motion.skeleton, motion.rotations[idx], motion.root[idx], motion.fps)


@functools.lru_cache(maxsize=256)
def spread_index(frames: int, n: int) -> np.ndarray:
    """The indices of :func:`spread_frames`: at most ``n`` of ``frames``, evenly spread
    (memoised: clips of a folder share lengths; read only)."""
    idx = np.unique(np.linspace(0, frames - 1, n).astype(int))
    idx.flags.writeable = False
    return idx


def median(x: np.ndarray) -> np.ndarray:
    """``np.median(x, axis=0)`` of a few rows (..., the same numbers) by one sort: np.median
    costs 70 us a call in numpy 2.0, which adds up over a folder's clips."""
    s, half = np.sort(x, axis=0), len(x) // 2
    return s[half] if len(x) % 2 else (s[half - 1] + s[half]) / 2


def detect_up(motion: Motion) -> str:
    """``"y"`` or ``"z"``: the axis along which the legs-to-head vector points (see module)."""
    parts = motion.skeleton.body_map or {}
    top = next((p for p in ("head", "neck", "chest") if p in parts), None)
    bottom = next(([f"{s}_{p}" for s in ("left", "right")] for p in ("ankle", "knee")
                   if f"left_{p}" in parts and f"right_{p}" in parts), None)
    if top is None or bottom is None:
        return "y"
    idx, sk = spread_index(motion.num_frames, _DETECT_FRAMES), motion.skeleton
    pos = joint_positions(motion.rotations[idx], motion.root[idx], sk.offsets, sk.parents,
                          [sk.part(p) for p in [top] + bottom])  # (T, 3, 3)
    up = median(pos[:, 0] - (pos[:, 1] + pos[:, 2]) / 2)  # (3,) x, y, z; legs' mean
    return "z" if up[2] > up[1] else "y"


def resolve_up(motion: Motion, up: str) -> str:
    """``"y"`` or ``"z"``: ``up`` itself, or detected by :func:`detect_up` when ``"auto"``."""
    up = check_up(up)
    return detect_up(motion) if up == "auto" else up


def to_y_up(motion: Motion, up: str, path: str | Path | None = None) -> Motion:
    """``motion`` turned Y up: unchanged when ``up`` is ``"y"`` (or detected so by ``"auto"``),
    rotated by :data:`Z_TO_Y` when it is ``"z"``.

    The whole rig is turned, rest pose included: offsets, End Sites and root path are rotated
    and every local rotation is conjugated (``C q C^-1``), so world positions become ``C p``.
    """
    if resolve_up(motion, up) == "y":
        return motion
    sk = motion.skeleton
    c = Z_TO_Y
    skeleton = Skeleton(list(sk.names), sk.parents.copy(), qrot(c, sk.offsets),
                        {k: qrot(c, np.asarray(v)) for k, v in sk.end_sites.items()},
                        sk.body_map)
    rotations = qmul(qmul(c, motion.rotations), qinv(c))
    try:
        return Motion(skeleton, rotations, qrot(c, motion.root), motion.fps, motion.name)
    except ValueError as e:  # cannot happen for a valid motion; kept as the reader's error
        raise FormatError(path or motion.name, None, str(e)) from None


def check_skip(frames: int, total: int, path: str | Path) -> None:
    """Refuse to skip ``frames`` leading frames (a prepended T-pose, say) of ``total``
    unless some remain."""
    if isinstance(frames, bool) or not isinstance(frames, (int, np.integer)) or frames < 0:
        raise ValueError(f"skip_frames must be an integer of at least 0, got {frames!r}")
    if frames >= total:
        raise FormatError(path, None, f"skipping {frames} leading frames leaves none of its "
                          f"{total}; expected fewer")
