"""Post-processing shared by the methods: feet pinned during contact."""

from __future__ import annotations

import numpy as np

from imuloco.core.motion import Motion


def pin_feet(motion: Motion, contacts: np.ndarray, feet: tuple[str, ...] = ("left_ankle",
             "right_ankle")) -> Motion:
    """Remove foot skating by moving the root so that feet in contact do not slide.

    Each frame's horizontal root step is replaced by the one that keeps the contact foot's
    world position still (the mean over feet in contact, weighted by contact probability);
    frames with no foot in contact keep their own step. Heights are untouched.

    Parameters
    ----------
    motion : the reconstruction.
    contacts : ndarray, shape (T, len(feet)), contact probabilities or booleans per foot.
    feet : body parts whose contact is given.
    """
    contacts = np.asarray(contacts, dtype=np.float64)
    pos = motion.positions()
    idx = [motion.skeleton.part(f) for f in feet]
    rel = pos[:, idx, :] - motion.root[:, None, :]          # feet relative to the root (T, F, 3)
    step = np.diff(motion.root, axis=0)                       # own root steps (T-1, 3)
    w = np.minimum(contacts[1:], contacts[:-1])               # in contact at both ends of a step
    pinned = -np.diff(rel, axis=0)                            # root step that keeps a foot still
    wsum = w.sum(axis=1, keepdims=True)
    blend = np.clip(wsum, 0.0, 1.0)
    target = np.where(wsum > 0, (w[..., None] * pinned).sum(1) / np.maximum(wsum, 1e-9), step)
    new_step = step.copy()
    new_step[:, [0, 2]] = (1 - blend) * step[:, [0, 2]] + blend * target[:, [0, 2]]
    root = motion.root.copy()
    root[1:, [0, 2]] = motion.root[0, [0, 2]] + np.cumsum(new_step[:, [0, 2]], axis=0)
    return Motion(motion.skeleton, motion.rotations, root, motion.fps, motion.name)
