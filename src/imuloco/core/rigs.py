"""Rig presets: the same motion with the joint names, hierarchy and T-pose rest an animation
tool expects (``--rig``).

The T-pose is found per body part: each canonical part's anatomical frame (long axis along the
segment, second axis forward, measured in the rig's own poses: :class:`Rig`) is put where it
is in a T-pose facing +Z, Y up (spine, neck and head up, legs down, arms out along +-X, palms
down, feet forward and flat by the rig's flat-foot pitch). Joints that stand for no part
(clavicles, extra spine joints) keep their mean pose relative to their parent. The motion is
then re-expressed on that rest (:mod:`imuloco.ops.restpose`): every joint's world position is
unchanged in every frame, and a zero local rotation is the T-pose.

Presets rename the canonical parts, and a joint between the shoulder's part and the chest's
(the clavicle) to the tool's names; where the tool has a joint the skeleton has not (Mixamo's
``Spine1``, Unreal's ``spine_02``: a third spine joint) it is inserted half way along the
segment, rigid with its parent (its local rotation is always zero). Joints a preset does not
name keep theirs. No preset moves a joint: ``mixamo``, ``unreal`` and ``unity`` are the
``bvh-default`` joints renamed (and one inserted), in metres, Y up, facing +Z.

- ``bvh-default``: the model's joint names, T-pose rest.
- ``mixamo``: ``mixamorig:Hips``, ``Spine``, ``Spine1``, ``Spine2``, ``LeftShoulder``,
  ``LeftArm``, ``LeftForeArm``, ``LeftHand``, ``LeftUpLeg``, ``LeftLeg``, ``LeftFoot``,
  ``LeftToeBase``, ... (Mixamo's rig: T-pose).
- ``unreal``: the UE4 mannequin's ``pelvis``, ``spine_01``..``spine_03``, ``neck_01``,
  ``head``, ``clavicle_l``, ``upperarm_l``, ``lowerarm_l``, ``hand_l``, ``thigh_l``,
  ``calf_l``, ``foot_l``, ``ball_l``, ... without its ``root`` bone on the floor (a
  Motion translates its top joint, here the pelvis); the mannequin rests in an A-pose, which
  Unreal's IK Retargeter's retarget pose bridges.
- ``unity``: Unity Humanoid's HumanBodyBones names (``Hips``, ``Spine``, ``Chest``,
  ``LeftShoulder``, ``LeftUpperArm``, ``LeftLowerArm``, ``LeftUpperLeg``, ``LeftToes``, ...),
  which its Avatar maps automatically; T-pose.
- ``model``: the model's training skeleton as it is (its own rest pose: the Bandai-Namco
  rig's is every bone along +X), what ``reconstruct`` wrote before the presets.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imuloco.core.bodymap import PARTS
from imuloco.core.motion import Motion
from imuloco.core.retarget import Rig, check_mapped
from imuloco.core.skeleton import Skeleton
from imuloco.errors import UnknownNameError
from imuloco.limits import MODEL_RIG, RIG_NAMES, RIG_PRESETS
from imuloco.ops.restpose import rebase_offsets, rebase_rotations
from imuloco.ops.rotations import IDENTITY, from_matrix, qinv, qmul, qrot

_X, _Y, _Z = np.eye(3)


def _frame(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    return from_matrix(np.stack([x, y, z], axis=-1))


# Each part's anatomical frame in the T-pose (:func:`imuloco.core.retarget.anatomical_frames`:
# y the long axis, z the second axis: forward, the pelvis's up, the feet's left; x = y x z),
# facing +Z with its left along +X.
_LEG, _FOOT = _frame(-_X, -_Y, _Z), _frame(_Y, _Z, _X)
_ARM = {"left": _frame(-_Y, _X, _Z), "right": _frame(_Y, -_X, _Z)}
TPOSE_FRAMES: dict[str, np.ndarray] = {
    "pelvis": _frame(_Z, _X, _Y),
    **{p: IDENTITY for p in ("spine", "chest", "neck", "head")},
    **{f"{s}_{p}": _LEG for s in ("left", "right") for p in ("hip", "knee")},
    **{f"{s}_{p}": _FOOT for s in ("left", "right") for p in ("ankle", "toe")},
    **{f"{s}_{p}": _ARM[s] for s in ("left", "right") for p in ("shoulder", "elbow", "wrist")},
}


@dataclass(frozen=True)
class RigPreset:
    """An animation tool's joint names. ``parts``: canonical part -> name, ``clavicle``: the
    joint between the chest and the shoulder, ``inserted``: the name of a joint added between
    the spine and chest parts when the skeleton has none there (or None); ``{Side}`` is
    ``Left``/``Right``, ``{s}`` ``l``/``r``; ``prefix`` goes before every name."""

    name: str
    parts: dict[str, str] | None  # None: the model's own names
    clavicle: str = ""
    inserted: str | None = None
    prefix: str = ""

    def part_name(self, part: str) -> str:
        assert self.parts is not None
        if part in self.parts:
            return self.parts[part]
        side, limb = part.split("_", 1)
        return self.parts[limb].format(Side=side.capitalize(), s=side[0])


def _limbs(hip: str, knee: str, ankle: str, toe: str, shoulder: str, elbow: str,
           wrist: str) -> dict[str, str]:
    return {"hip": hip, "knee": knee, "ankle": ankle, "toe": toe, "shoulder": shoulder,
            "elbow": elbow, "wrist": wrist}


PRESETS: dict[str, RigPreset] = {p.name: p for p in (
    RigPreset("bvh-default", None),
    RigPreset("mixamo", {"pelvis": "Hips", "spine": "Spine", "chest": "Spine2", "neck": "Neck",
                         "head": "Head",
                         **_limbs("{Side}UpLeg", "{Side}Leg", "{Side}Foot", "{Side}ToeBase",
                                  "{Side}Arm", "{Side}ForeArm", "{Side}Hand")},
              "{Side}Shoulder", "Spine1", "mixamorig:"),
    RigPreset("unreal", {"pelvis": "pelvis", "spine": "spine_01", "chest": "spine_03",
                         "neck": "neck_01", "head": "head",
                         **_limbs("thigh_{s}", "calf_{s}", "foot_{s}", "ball_{s}",
                                  "upperarm_{s}", "lowerarm_{s}", "hand_{s}")},
              "clavicle_{s}", "spine_02"),
    RigPreset("unity", {"pelvis": "Hips", "spine": "Spine", "chest": "Chest", "neck": "Neck",
                        "head": "Head",
                        **_limbs("{Side}UpperLeg", "{Side}LowerLeg", "{Side}Foot",
                                 "{Side}Toes", "{Side}UpperArm", "{Side}LowerArm",
                                 "{Side}Hand")},
              "{Side}Shoulder"),
)}
MODEL = MODEL_RIG  # the model's skeleton as it is, no preset
DEFAULT_RIG = "bvh-default"  # what reconstruct, batch and demo write without --rig
if tuple(PRESETS) != RIG_PRESETS:  # the names the CLI shows, from the import-light module
    raise RuntimeError(f"imuloco.limits.RIG_PRESETS {RIG_PRESETS} must name PRESETS in order, "
                       f"{tuple(PRESETS)}")


def check_rig_name(name: str) -> str:
    """``name`` when it is a preset (or ``model``); else :class:`UnknownNameError`."""
    if name not in RIG_NAMES:
        raise UnknownNameError(f"unknown rig {name!r}; expected one of {', '.join(RIG_NAMES)}")
    return name


def tpose_rest(rig: Rig) -> np.ndarray:
    """The global rotations (J, 4) of ``rig``'s joint frames in its T-pose (see the module):
    ``T_part A_part^-1`` for a part's joint (``A_part``: :attr:`Rig.frames`, the anatomical
    frame in the joint's frame), the parent's times the mean local rotation
    (:attr:`Rig.neutral`) for the others, the identity above the root."""
    sk = rig.skeleton
    by_joint = {sk.part(p): k for k, p in enumerate(PARTS)}
    rest = np.empty((sk.num_joints, 4))
    for j, p in enumerate(sk.parents):
        if j in by_joint:
            k = by_joint[j]
            rest[j] = qmul(TPOSE_FRAMES[PARTS[k]], qinv(rig.frames[k]))
        else:
            rest[j] = rig.neutral[j] if p < 0 else qmul(rest[p], rig.neutral[j])
    return rest


def rebased(motion: Motion, rest: np.ndarray) -> Motion:
    """``motion`` re-expressed on the rest pose whose joint frames have global rotations
    ``rest`` (J, 4) (:mod:`imuloco.ops.restpose`): same world positions; its skeleton's
    offsets are the rest pose's bone vectors and End Sites turn with their joints."""
    sk = motion.skeleton
    offsets = rebase_offsets(sk.offsets, sk.parents, rest)
    ends = {j: qrot(rest[j], v) for j, v in sk.end_sites.items()}
    new = Skeleton(list(sk.names), sk.parents.copy(), offsets, ends, dict(sk.body_map or {}))
    return Motion(new, rebase_rotations(motion.rotations, sk.parents, rest), motion.root.copy(),
                  motion.fps, motion.name)


def measure_rest(motion: Motion) -> np.ndarray:
    """The T-pose rest (J, 4) of ``motion``'s skeleton (:func:`tpose_rest`), its rig measured
    on ``motion``'s own poses (:meth:`Rig.measure`)."""
    return tpose_rest(Rig.measure([motion], where=motion.name or "motion"))


def apply_rig(motion: Motion, name: str = DEFAULT_RIG, rest: np.ndarray | None = None
              ) -> Motion:
    """``motion`` on preset ``name`` (:data:`RIG_NAMES`): T-pose rest, the preset's names and
    hierarchy; world joint positions unchanged. ``rest``: the T-pose rest of its skeleton
    (:func:`measure_rest`; measured on ``motion`` when None: give it to convert the pieces of
    one recording alike)."""
    check_rig_name(name)
    if name == MODEL:
        return motion
    check_mapped(motion.skeleton, motion.name or "motion")
    out = rebased(motion, measure_rest(motion) if rest is None else rest)
    preset = PRESETS[name]
    return out if preset.parts is None else _renamed(out, preset)


def _between(sk: Skeleton, lower: int, upper: int) -> list[int]:
    """Joints strictly between ``upper`` and its descendant ``lower``, top down."""
    chain = []
    j = int(sk.parents[lower])
    while j > upper:
        chain.append(j)
        j = int(sk.parents[j])
    return chain[::-1] if j == upper else []


def _renamed(motion: Motion, preset: RigPreset) -> Motion:
    """A T-posed ``motion`` with ``preset``'s names (and inserted spine joint)."""
    sk = motion.skeleton
    names = {sk.part(p): preset.part_name(p) for p in PARTS}
    for side in ("left", "right"):
        clav = _between(sk, sk.part(f"{side}_shoulder"), sk.part("chest"))
        if len(clav) == 1:
            names[clav[0]] = preset.clavicle.format(Side=side.capitalize(), s=side[0])
    spine, chest = sk.part("spine"), sk.part("chest")
    middle = _between(sk, chest, spine)
    insert = preset.inserted is not None and not middle and sk.parents[chest] == spine
    if preset.inserted is not None and len(middle) == 1:
        names[middle[0]] = preset.inserted
    order = [j for i in range(sk.num_joints) for j in ((i, -1) if insert and i == spine else
                                                        (i,))]
    new_index = {j: k for k, j in enumerate(order)}  # -1: the inserted joint
    parents, offsets, rot = [], [], []
    for j in order:
        if j == -1:
            parents.append(new_index[spine])
            offsets.append(0.5 * sk.offsets[chest])
            rot.append(np.broadcast_to(IDENTITY, motion.rotations[:, 0].shape))
            continue
        p = int(sk.parents[j])
        parents.append(-1 if p < 0 else new_index[-1] if insert and j == chest
                       else new_index[p])
        offsets.append(0.5 * sk.offsets[j] if insert and j == chest else sk.offsets[j])
        rot.append(motion.rotations[:, j])
    full = [preset.prefix + (preset.inserted if j == -1 else names.get(j, sk.names[j]))
            for j in order]
    ends = {new_index[j]: v for j, v in sk.end_sites.items()}
    body = {p: preset.prefix + preset.part_name(p) for p in PARTS}
    new = Skeleton(full, np.array(parents), np.array(offsets), ends, body)
    return Motion(new, np.stack(rot, axis=1), motion.root.copy(), motion.fps, motion.name)
