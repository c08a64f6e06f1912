"""Retargeting: a motion moved onto another skeleton by canonical body part.

Each canonical part (:data:`imuloco.core.bodymap.PARTS`) keeps its *global* rotation, corrected
for how each rig's joint frames sit on the bone (the rest-pose correction): a part's anatomical
frame (long axis along the segment, z forward, from :func:`imuloco.ops.retarget.segment_frames`)
is measured in the rig's own poses and expressed in the joint's frame (a :class:`Rig`), and
``G_target = G_source A_source A_target^-1`` (:func:`imuloco.ops.retarget.transfer`). A foot's
frame is pitched up by the rig's own flat-foot pitch (:attr:`Rig.foot_pitch`), so that its long
axis lies on the floor when the foot stands flat: rigs put their toe joint at other places on
the foot (Bandai-Namco's at the sole, 40 degrees below the ankle joint; Character Creator's
inside the foot, 14 below), and copying the ankle-to-toe direction would tip a flat foot's toes
up or down by the difference. Joints
that stand for no part (twist, share, finger and face bones, clavicles, extra spine joints)
take their mean local rotation over the target rig's poses. The root path is the source
pelvis's scaled by the ratio of leg lengths (target / source), and the result is moved up or
down so that its feet stand on the floor where the source's did (a low percentile of the
lowest foot joint's height, as :func:`imuloco.core.contacts.floor_height`).

Two skeletons with the same joint names and parents are one rig family (same joint frames,
other bone lengths): there the local rotations are copied as they are (every joint angle is
kept, fingers and clavicles included) and only the root path is scaled.

What retargeting drops is in ``docs/glossary.md`` (twist bones, fingers, face, proportions).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from imuloco.core.bodymap import PARTS, BodyMapError
from imuloco.core.contacts import flat_foot_pitch, foot_pitches
from imuloco.core.motion import Motion
from imuloco.core.skeleton import Skeleton
from imuloco.ops.kinematics import fk
from imuloco.ops.retarget import (
    assemble,
    body_axes,
    joint_local,
    mean_rotation,
    segment_frames,
    transfer,
)
from imuloco.ops.rotations import from_rotvec, normalize, qmul, slerp

# part -> (start, end) of the segment that gives its long axis, and whether the frame's second
# axis is the body's left (feet, whose long axis points forward) rather than its forward.
# Parts without a distal part of their own (head, wrists, toes) use their parent segment:
# their anatomical frame is the parent's in the rig's mean pose.
_SEGMENTS: dict[str, tuple[str, str, bool]] = {
    "spine": ("spine", "chest", False), "chest": ("chest", "neck", False),
    "neck": ("neck", "head", False), "head": ("neck", "head", False),
    **{f"{s}_{a}": (f"{s}_{a}", f"{s}_{b}", a in ("ankle",))
       for s in ("left", "right")
       for a, b in (("hip", "knee"), ("knee", "ankle"), ("ankle", "toe"), ("shoulder", "elbow"),
                    ("elbow", "wrist"))},
    **{f"{s}_toe": (f"{s}_ankle", f"{s}_toe", True) for s in ("left", "right")},
    **{f"{s}_wrist": (f"{s}_elbow", f"{s}_wrist", False) for s in ("left", "right")},
}
FEET = ("left_ankle", "left_toe", "right_ankle", "right_toe")
MAX_POSES = 600  # poses a rig is measured in (evenly spaced over the given clips)
MAX_PITCH_CLIPS = 20  # clips (evenly spaced) whose flat feet give a rig's foot pitch,
MAX_PITCH_FRAMES = 3000  # and frames of each (100 s at 30 fps; every shared clip is shorter)


def check_mapped(skeleton: Skeleton, where: str) -> None:
    """Raise :class:`BodyMapError` naming ``where`` (a file or clip) and the canonical parts
    its skeleton does not map."""
    missing = [p for p in PARTS if p not in (skeleton.body_map or {})]
    if missing:
        raise BodyMapError(
            f"{where}: cannot map body parts {missing} to its joints "
            f"({skeleton.num_joints}: {', '.join(skeleton.names[:12])}"
            f"{', ...' if skeleton.num_joints > 12 else ''}); expected joint names the body "
            "map knows (imuloco.core.bodymap: Bandai-Namco, CMU, Mixamo, Character Creator)")


def anatomical_frames(skeleton: Skeleton, positions: np.ndarray) -> np.ndarray:
    """World anatomical frames of every canonical part, (T, P, 4), from joint positions
    (T, J, 3) of poses of ``skeleton``."""
    pos = {p: positions[:, skeleton.part(p)] for p in PARTS}
    up, left, forward = body_axes(pos["left_hip"], pos["right_hip"])
    frames = []
    for part in PARTS:
        if part == "pelvis":  # the hip line, with up: both rigid with the pelvis
            frames.append(segment_frames(pos["left_hip"] - pos["right_hip"], up, forward))
            continue
        start, end, lateral = _SEGMENTS[part]
        axis = pos[end] - pos[start]
        second, fallback = (left, up) if lateral else (forward, up)
        frames.append(segment_frames(axis, second, fallback))
    return np.stack(frames, axis=1)


@dataclass(frozen=True, eq=False)
class Rig:
    """A skeleton measured in poses it takes, as retargeting needs it.

    Attributes
    ----------
    skeleton : Skeleton, mapping every canonical part.
    frames : ndarray, shape (P, 4): each part's anatomical frame in its joint's frame.
    neutral : ndarray, shape (J, 4): each joint's mean local rotation over the poses (for
        joints that stand for no part).
    foot_pitch : radians, the ankle-to-toe direction's angle against the floor when a foot
        stands flat (negative: the toe joint lower), by which the feet's frames are pitched.
    """

    skeleton: Skeleton
    frames: np.ndarray
    neutral: np.ndarray
    foot_pitch: float = 0.0

    @classmethod
    def measure(cls, motions: Sequence[Motion], where: str | None = None) -> Rig:
        """The rig of ``motions`` (clips of one skeleton; at most :data:`MAX_POSES` frames
        are used, evenly spaced). ``where`` names them in errors.

        The flat-foot pitch is :func:`imuloco.core.contacts.flat_foot_pitch` of the
        motions (feet with heel and toe on the floor) over the first
        :data:`MAX_PITCH_FRAMES` of at most :data:`MAX_PITCH_CLIPS`, evenly spaced: finding
        contacts took 6 s on a 640 s reconstruction, which ``reconstruct --skeleton``
        measures. Motions without such a frame (one T-pose, sprints) give the median pitch
        of their poses, which a T-pose stands flat in.
        """
        sk = motions[0].skeleton
        check_mapped(sk, where or motions[0].name or "motion")
        rot = np.concatenate([m.rotations for m in motions])
        step = max(1, len(rot) // MAX_POSES)
        rot = normalize(rot[::step])
        glob, pos = fk(rot, np.zeros((len(rot), 3)), sk.offsets, sk.parents)
        pitch = flat_foot_pitch(m.slice(0, MAX_PITCH_FRAMES)
                                for m in motions[:: max(1, len(motions) // MAX_PITCH_CLIPS)])
        if pitch is None:
            pitch = float(np.median(foot_pitches(sk, pos)))
        idx = [sk.part(p) for p in PARTS]
        frames = joint_local(glob[:, idx], anatomical_frames(sk, pos))
        feet = [PARTS.index(p) for p in FEET]  # the ankle and toe parts: ankle-to-toe axis
        frames[feet] = qmul(frames[feet], from_rotvec(np.array([0.0, 0.0, pitch])))  # about
        # the frame's lateral z axis: its y axis, ankle to toe, turned onto the floor
        return cls(sk, frames, mean_rotation(rot), pitch)


def same_family(a: Skeleton, b: Skeleton) -> bool:
    """Whether two skeletons share joint names and parents (hence joint frames)."""
    return a.names == b.names and np.array_equal(a.parents, b.parents)


def retarget(motion: Motion, target: Rig | Skeleton, source: Rig | None = None) -> Motion:
    """``motion`` on ``target``'s skeleton (see the module docstring).

    Parameters
    ----------
    motion : the motion to move.
    target : the rig to move it onto (:meth:`Rig.measure`); a bare Skeleton will do within
        one rig family (:func:`same_family`).
    source : the rig of ``motion``'s skeleton; measured on ``motion`` itself when None
        (not needed within one rig family).
    """
    src = motion.skeleton
    dst = target if isinstance(target, Skeleton) else target.skeleton
    check_mapped(src, motion.name or "motion")
    scale = dst.leg_length() / src.leg_length()
    if same_family(src, dst):
        out = Motion(dst, motion.rotations.copy(), motion.root * scale, motion.fps, motion.name)
    elif isinstance(target, Skeleton):
        raise ValueError(f"{motion.name or 'motion'}: retargeting onto another rig family "
                         "needs the target's Rig (Rig.measure), not a bare Skeleton")
    else:
        source = Rig.measure([motion]) if source is None else source
        glob, pos = motion.fk()
        wanted = transfer(glob[:, [src.part(p) for p in PARTS]], source.frames, target.frames)
        local, rel = assemble(dst.parents, dst.offsets, target.neutral,
                              {dst.part(p): wanted[:, k] for k, p in enumerate(PARTS)})
        root = scale * pos[:, src.part("pelvis")] - rel[:, dst.part("pelvis")]
        out = Motion(dst, local, root, motion.fps, motion.name)
    out.root[:, 1] += scale * _floor(motion) - _floor(out)
    return out


def _floor(motion: Motion) -> float:
    """The floor under a motion's feet: the 5th percentile of the lowest foot joint's height
    (as :func:`imuloco.core.contacts.floor_height`)."""
    return float(np.percentile(motion.part_positions(list(FEET))[..., 1].min(axis=1), 5.0))


def resampled(motion: Motion, fps: float) -> Motion:
    """``motion`` at another frame rate: local rotations by slerp, the root linearly, over
    the same span (the last frame at or before the original's last time)."""
    if abs(fps - motion.fps) < 1e-6 * fps:
        return motion
    if motion.num_frames < 2:
        return Motion(motion.skeleton, motion.rotations, motion.root, float(fps), motion.name)
    times = motion.times
    new_t = np.arange(int(np.floor(times[-1] * fps + 1e-6)) + 1) / fps
    rot = slerp(motion.rotations, times, new_t)
    root = np.stack([np.interp(new_t, times, motion.root[:, k]) for k in range(3)], axis=1)
    return Motion(motion.skeleton, rot, root, float(fps), motion.name)
