"""Canonical body parts and the maps from each dataset's joint names to them.

Sensors, contacts and metrics refer to body parts (``"right_ankle"``), never to a dataset's
joint names. A body map is a ``dict`` from part to joint name. Built-in candidate names cover
the Bandai-Namco skeleton of the shared data, the CMU skeleton (ASF/AMC bone names and the common
BVH conversions of it), Character Creator / iClone / ActorCore (``CC_Base_*``; their twist, share,
finger and face bones stay unmapped), Unreal's mannequin (``pelvis``, ``spine_01``, ``thigh_l``,
...; ``spine_03`` the chest), Unity Humanoid's bone names and common BVH naming (Mixamo and
similar). A user gives their own map by
passing ``overrides`` to :func:`resolve_body_map` or a ``body_map`` to :class:`Skeleton`.
"""

from __future__ import annotations

import re

from imuloco.errors import ImulocoError

BodyMap = dict[str, str]

SIDES = ("left", "right")
LIMB_PARTS = ("hip", "knee", "ankle", "toe", "shoulder", "elbow", "wrist")
CENTRE_PARTS = ("pelvis", "spine", "chest", "neck", "head")
PARTS: tuple[str, ...] = CENTRE_PARTS + tuple(f"{s}_{p}" for s in SIDES for p in LIMB_PARTS)
UPPER_PARTS = ("spine", "chest", "neck", "head") + tuple(
    f"{s}_{p}" for s in SIDES for p in ("shoulder", "elbow", "wrist"))
LOWER_PARTS = tuple(f"{s}_{p}" for s in SIDES for p in ("hip", "knee", "ankle", "toe"))
# the body-part groups the bench scores apart: what a leg sensor sees (legs), what it cannot
# (arms), and what follows from the legs (trunk)
PART_GROUPS: dict[str, tuple[str, ...]] = {
    "legs": LOWER_PARTS,
    "arms": tuple(f"{s}_{p}" for s in SIDES for p in ("shoulder", "elbow", "wrist")),
    "trunk": ("spine", "chest", "neck", "head"),
}

# Candidate joint names per part, most specific first. "{S}" is the side's letter (L/R),
# "{Side}" the side's word (Left/Right), "{s}" the lower-case letter (l/r).
_CENTRE_CANDIDATES: dict[str, tuple[str, ...]] = {
    "pelvis": ("Hips", "root", "CC_Base_Hip", "Pelvis", "Hip"),
    # CMU: the ASF joint "upperback" (where the lowerback bone ends) is the one the CMU BVH
    # conversions call "Spine"; "lowerback" sits on the root.
    # Character Creator: Hip > Waist > Spine01 > Spine02 > NeckTwist01 > NeckTwist02 > Head;
    # Spine01 and Spine02 sit where Bandai-Namco's Spine and Chest do.
    "spine": ("Spine", "upperback", "lowerback", "LowerBack", "Spine1", "CC_Base_Spine01",
              "spine_01"),
    "chest": ("Chest", "thorax", "Spine2", "Spine1", "upperback", "UpperChest",
              "CC_Base_Spine02", "spine_03"),
    "neck": ("Neck", "lowerneck", "Neck1", "upperneck", "CC_Base_NeckTwist01", "neck_01"),
    "head": ("Head", "CC_Base_Head"),
}
_LIMB_CANDIDATES: dict[str, tuple[str, ...]] = {
    "hip": ("UpperLeg_{S}", "{Side}UpLeg", "{s}femur", "{Side}Hip", "{Side}UpperLeg", "{Side}Thigh",
            "{S}_Hip", "CC_Base_{S}_Thigh", "thigh_{s}"),
    "knee": ("LowerLeg_{S}", "{Side}Leg", "{s}tibia", "{Side}Knee", "{Side}LowerLeg", "{Side}Shin",
             "{S}_Knee", "CC_Base_{S}_Calf", "calf_{s}"),
    "ankle": ("Foot_{S}", "{Side}Foot", "{s}foot", "{Side}Ankle", "{S}_Ankle", "CC_Base_{S}_Foot",
              "foot_{s}"),
    "toe": ("Toes_{S}", "{Side}ToeBase", "{s}toes", "{Side}Toe", "{Side}Toes", "{Side}Toe_End",
            "{S}_Foot", "CC_Base_{S}_ToeBase", "ball_{s}"),
    "shoulder": ("UpperArm_{S}", "{Side}Arm", "{s}humerus", "{Side}UpperArm", "{Side}Shoulder",
                 "{S}_Shoulder", "CC_Base_{S}_Upperarm", "upperarm_{s}"),
    "elbow": ("LowerArm_{S}", "{Side}ForeArm", "{s}radius", "{Side}Elbow", "{Side}LowerArm",
              "{S}_Elbow", "CC_Base_{S}_Forearm", "lowerarm_{s}"),
    "wrist": ("Hand_{S}", "{Side}Hand", "{s}wrist", "{Side}Wrist", "{s}hand", "{S}_Wrist",
              "CC_Base_{S}_Hand", "hand_{s}"),
}


class BodyMapError(ImulocoError, KeyError):
    """A skeleton's joint names could not be mapped to every canonical body part."""

    def __str__(self) -> str:  # KeyError quotes its message; we want it plain
        return str(self.args[0])


def _normalise(name: str) -> str:
    """Joint names compare case-insensitively, without namespace prefixes like ``mixamorig:``."""
    return re.sub(r"^.*[:|]", "", name).lower()


def candidates(part: str) -> tuple[str, ...]:
    """Candidate joint names for a canonical part, in order of preference."""
    if part in _CENTRE_CANDIDATES:
        return _CENTRE_CANDIDATES[part]
    side, limb = part.split("_", 1)
    fill = {"S": side[0].upper(), "Side": side.capitalize(), "s": side[0]}
    return tuple(c.format(**fill) for c in _LIMB_CANDIDATES[limb])


def resolve_body_map(
    names: list[str], overrides: BodyMap | None = None, strict: bool = True
) -> BodyMap:
    """Map each canonical body part to one of ``names``.

    Parameters
    ----------
    names : the skeleton's joint names.
    overrides : part -> joint name given by the user; these win over the built-in candidates.
    strict : raise :class:`BodyMapError` listing the unmapped parts when any part is missing.
    """
    lookup = {_normalise(n): n for n in names}
    result: BodyMap = {}
    for part, joint in (overrides or {}).items():
        if part not in PARTS:
            raise BodyMapError(f"unknown body part {part!r} in the map; parts are {list(PARTS)}")
        if joint not in names:
            raise BodyMapError(f"body map names joint {joint!r} for {part!r}, not in the skeleton")
        result[part] = joint
    for part in PARTS:
        if part in result:
            continue
        for cand in candidates(part):
            if _normalise(cand) in lookup and lookup[_normalise(cand)] not in result.values():
                result[part] = lookup[_normalise(cand)]
                break
    missing = [p for p in PARTS if p not in result]
    if strict and missing:
        raise BodyMapError(
            f"cannot map body parts {missing} to joints {names}; pass a map for them, e.g. "
            f"resolve_body_map(names, overrides={{'{missing[0]}': '<joint name>'}})"
        )
    return result
