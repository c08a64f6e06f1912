"""The neutral poses the per-part fallback moves toward (:mod:`imuloco.methods.fallback`),
built from training motion: the standing pose from the frames where both shanks are still
(by the rule's own still test on virtual shin sensors) with the walking pose's hanging arms,
the walking pose from every frame of
locomotion clips, each with the squared error it is expected to miss per body-part group.
``benchmarks/build_neutral.py`` writes the shipped file."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from imuloco.core.motion import Motion
from imuloco.measures.metrics import joint_errors
from imuloco.methods import pose
from imuloco.methods.fallback import (
    FEET,
    GROUPS,
    FallbackRule,
    NeutralPoses,
    joint_groups,
    position_groups,
)
from imuloco.methods.training import Example
from imuloco.ops.rotations import from_6d, normalize

SHANKS = ("right_ankle", "left_ankle")


def mean_pose(clips: Sequence[Motion], masks: Sequence[np.ndarray | None]) -> np.ndarray:
    """The mean pose (J, 4) of the selected frames (``masks``: boolean (T,) per clip, None for
    all): 6-D rotations averaged, as the ``mean`` baseline does (:mod:`imuloco.methods.pose`);
    the root's relative to its heading."""
    j = clips[0].skeleton.num_joints
    vec = np.concatenate([pose.encode(m)[slice(None) if k is None else k, :6 * j]
                          for m, k in zip(clips, masks)])
    if not len(vec):
        raise ValueError("neutral poses: no frame to average")
    return normalize(from_6d(vec.mean(0).reshape(j, 6)))


def group_sq_errors(clips: Sequence[Motion], masks: Sequence[np.ndarray | None],
                    rot: np.ndarray) -> np.ndarray:
    """:attr:`NeutralPoses.sq_error_m2` of one activity (G,): the pose ``rot`` (J, 4) held
    on each clip's selected frames against the clip, per group of :func:`position_groups`."""
    total, frames = np.zeros(len(GROUPS)), 0
    for m, k in zip(clips, masks):
        held = Motion(m.skeleton, np.broadcast_to(rot, (m.num_frames, *rot.shape)), m.root,
                      m.fps)
        err = joint_errors(m, held)[slice(None) if k is None else k]
        groups = position_groups(m.skeleton)
        for g in range(len(GROUPS)):
            total[g] += (err[:, groups == g] ** 2).sum() / (m.skeleton.num_joints - 1)
        frames += len(err)
    return total / max(frames, 1)


def still_frames(example: Example, rule: FallbackRule | None = None) -> np.ndarray:
    """Frames (T,) of an example simulated with both :data:`SHANKS` where both are still
    (still weight over 0.5)."""
    rule = FallbackRule() if rule is None else rule
    fps = example.motion.fps
    return np.all([rule.still(example.signals, fps, k) > 0.5 for k in range(len(SHANKS))], 0)


def build_neutral(still: Sequence[Example], moving: Sequence[Motion], source: str = "",
                  rule: FallbackRule | None = None) -> NeutralPoses:
    """Neutral poses from ``still`` (examples with both :data:`SHANKS` simulated; their still
    frames stand) and ``moving`` (locomotion clips, every frame). Every clip has the first
    ``still`` clip's joint names."""
    masks = [still_frames(e, rule) for e in still]
    clips = [e.motion for e in still]
    stand = mean_pose(clips, masks)
    walk = mean_pose(list(moving), [None] * len(moving))
    # the standing pose's arms hang as the walking pose's: the average of the gestures' arms
    # (half raised) missed more on left-out gestures than hanging arms (arms 23.9 against
    # 21.3 cm on the standing gestures: docs/results/actions/fallback.md)
    arms = joint_groups(clips[0].skeleton) == GROUPS.index("arms")
    stand[arms] = walk[arms]
    errors = np.stack([group_sq_errors(clips, masks, stand),
                       group_sq_errors(list(moving), [None] * len(moving), walk)])
    feet = [m.part_positions(list(FEET))[k][..., 1].min(axis=1) for m, k in zip(clips, masks)]
    return NeutralPoses(tuple(clips[0].skeleton.names), np.stack([stand, walk]),
                        float(np.median(np.concatenate(feet))), errors, source)
