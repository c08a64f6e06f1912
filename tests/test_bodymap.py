"""Body maps: built-in names of the shared data, Mixamo, CMU (ASF and BVH), user maps, errors."""

from __future__ import annotations

import pytest

from imuloco.core.bodymap import (
    LOWER_PARTS,
    PARTS,
    UPPER_PARTS,
    BodyMapError,
    candidates,
    resolve_body_map,
)
from imuloco.core.skeleton import Skeleton

BANDAI = ["Hips", "Spine", "Chest", "Neck", "Head", "Shoulder_L", "UpperArm_L", "LowerArm_L",
          "Hand_L", "Shoulder_R", "UpperArm_R", "LowerArm_R", "Hand_R", "UpperLeg_L",
          "LowerLeg_L", "Foot_L", "Toes_L", "UpperLeg_R", "LowerLeg_R", "Foot_R", "Toes_R"]

MIXAMO = ["mixamorig:" + n for n in [
    "Hips", "Spine", "Spine1", "Spine2", "Neck", "Head", "HeadTop_End",
    "LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand", "LeftHandIndex1",
    "RightShoulder", "RightArm", "RightForeArm", "RightHand", "RightHandIndex1",
    "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase", "LeftToe_End",
    "RightUpLeg", "RightLeg", "RightFoot", "RightToeBase", "RightToe_End"]]

# The CMU BVH conversions (cgspeed's): the hip bones and the clavicles are joints of their own.
CMU_BVH = ["Hips", "LHipJoint", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase", "RHipJoint",
           "RightUpLeg", "RightLeg", "RightFoot", "RightToeBase", "LowerBack", "Spine", "Spine1",
           "Neck", "Neck1", "Head", "LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand",
           "LeftFingerBase", "LeftHandIndex1", "LThumb", "RightShoulder", "RightArm",
           "RightForeArm", "RightHand", "RightFingerBase", "RightHandIndex1", "RThumb"]

LIMBS = ("hip", "knee", "ankle", "toe", "shoulder", "elbow", "wrist")


def sided(pattern: dict[str, str]) -> dict[str, str]:
    """Expand ``{"hip": "{Side}UpLeg"}`` to both sides."""
    out = {}
    for side in ("left", "right"):
        fill = {"Side": side.capitalize(), "S": side[0].upper(), "s": side[0]}
        out |= {f"{side}_{k}": v.format(**fill) for k, v in pattern.items()}
    return out


def test_parts():
    assert len(PARTS) == 19 and len(set(PARTS)) == 19
    assert set(UPPER_PARTS) | set(LOWER_PARTS) | {"pelvis"} == set(PARTS)
    assert not set(UPPER_PARTS) & set(LOWER_PARTS)


def test_bandai():
    bm = resolve_body_map(BANDAI)
    assert bm == {"pelvis": "Hips", "spine": "Spine", "chest": "Chest", "neck": "Neck",
                  "head": "Head"} | sided({
                      "hip": "UpperLeg_{S}", "knee": "LowerLeg_{S}", "ankle": "Foot_{S}",
                      "toe": "Toes_{S}", "shoulder": "UpperArm_{S}", "elbow": "LowerArm_{S}",
                      "wrist": "Hand_{S}"})


def test_bandai_unfolded_root():
    """Read with the static root kept, ``joint_Root`` is not mistaken for the pelvis."""
    assert resolve_body_map(["joint_Root"] + BANDAI)["pelvis"] == "Hips"


def test_mixamo():
    bm = resolve_body_map(MIXAMO)
    expected = {"pelvis": "Hips", "spine": "Spine", "chest": "Spine2", "neck": "Neck",
                "head": "Head"} | sided({
                    "hip": "{Side}UpLeg", "knee": "{Side}Leg", "ankle": "{Side}Foot",
                    "toe": "{Side}ToeBase", "shoulder": "{Side}Arm", "elbow": "{Side}ForeArm",
                    "wrist": "{Side}Hand"})
    assert bm == {k: "mixamorig:" + v for k, v in expected.items()}  # names as the file has them


def test_other_prefixes_and_case():
    names = [f"Armature|{n.removeprefix('mixamorig:').upper()}" for n in MIXAMO]
    bm = resolve_body_map(names)
    assert bm["left_knee"] == "Armature|LEFTLEG" and bm["chest"] == "Armature|SPINE2"


def test_cmu_bvh():
    bm = resolve_body_map(CMU_BVH)
    assert bm == {"pelvis": "Hips", "spine": "Spine", "chest": "Spine1", "neck": "Neck",
                  "head": "Head"} | sided({
                      "hip": "{Side}UpLeg", "knee": "{Side}Leg", "ankle": "{Side}Foot",
                      "toe": "{Side}ToeBase", "shoulder": "{Side}Arm", "elbow": "{Side}ForeArm",
                      "wrist": "{Side}Hand"})
    # LHipJoint (the pelvis bone) and LeftShoulder (the clavicle) are not the hip and shoulder
    assert "LHipJoint" not in bm.values() and "LeftShoulder" not in bm.values()


def test_smpl_names():
    smpl = ["Pelvis", "L_Hip", "R_Hip", "Spine1", "L_Knee", "R_Knee", "Spine2", "L_Ankle",
            "R_Ankle", "Spine3", "L_Foot", "R_Foot", "Neck", "L_Collar", "R_Collar", "Head",
            "L_Shoulder", "R_Shoulder", "L_Elbow", "R_Elbow", "L_Wrist", "R_Wrist"]
    bm = resolve_body_map(smpl)
    assert bm["left_toe"] == "L_Foot" and bm["left_ankle"] == "L_Ankle"
    assert bm["right_shoulder"] == "R_Shoulder" and bm["pelvis"] == "Pelvis"


def test_one_joint_per_part():
    for names in (BANDAI, MIXAMO, CMU_BVH):
        bm = resolve_body_map(names)
        assert len(set(bm.values())) == len(bm) == len(PARTS)
        assert set(bm.values()) <= set(names)


def test_unmappable_lists_the_missing_parts():
    with pytest.raises(BodyMapError) as e:
        resolve_body_map(["a", "b", "c"])
    msg = str(e.value)
    assert all(p in msg for p in PARTS) and "overrides" in msg
    # only what is missing is listed
    names = [n for n in BANDAI if not n.startswith("Toes")]
    with pytest.raises(BodyMapError) as e:
        resolve_body_map(names)
    missing = str(e.value).split("]")[0]
    assert "'left_toe'" in missing and "'right_toe'" in missing
    assert "'left_ankle'" not in missing and "'pelvis'" not in missing
    assert isinstance(e.value, KeyError)  # callers may catch it as a missing key


def test_not_strict_gives_what_it_can():
    names = [n for n in BANDAI if not n.startswith("Toes")]
    bm = resolve_body_map(names, strict=False)
    assert set(PARTS) - set(bm) == {"left_toe", "right_toe"}


def test_user_overrides():
    odd = ["pelvis_bone", "spine_a", "spine_b", "neck_a", "skull"] + [
        f"{s}_{limb}_x" for s in ("l", "r") for limb in LIMBS]
    with pytest.raises(BodyMapError):
        resolve_body_map(odd)
    user = {"pelvis": "pelvis_bone", "spine": "spine_a", "chest": "spine_b", "neck": "neck_a",
            "head": "skull"} | {f"{side}_{limb}": f"{side[0]}_{limb}_x"
                                for side in ("left", "right") for limb in LIMBS}
    assert resolve_body_map(odd, overrides=user) == user
    # overrides win over the built-in candidates; the others still resolve
    bm = resolve_body_map(BANDAI, overrides={"chest": "Spine", "spine": "Hips", "pelvis": "Chest"})
    assert (bm["chest"], bm["spine"], bm["pelvis"]) == ("Spine", "Hips", "Chest")
    assert bm["left_knee"] == "LowerLeg_L"
    # and a Skeleton takes a map
    sk = Skeleton(odd, [-1] + [0] * (len(odd) - 1), [[0, 0, 0]] * len(odd), body_map=user)
    assert sk.part("head") == odd.index("skull")


def test_bad_overrides():
    with pytest.raises(BodyMapError, match="unknown body part 'tail'"):
        resolve_body_map(BANDAI, overrides={"tail": "Hips"})
    with pytest.raises(BodyMapError, match="'Pelvis' for 'pelvis', not in the skeleton"):
        resolve_body_map(BANDAI, overrides={"pelvis": "Pelvis"})


def test_candidates_by_side():
    assert candidates("left_hip")[:3] == ("UpperLeg_L", "LeftUpLeg", "lfemur")
    assert candidates("right_wrist")[:3] == ("Hand_R", "RightHand", "rwrist")
    assert candidates("pelvis")[0] == "Hips"
