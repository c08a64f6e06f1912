"""Rig presets and the T-pose rest (imuloco.core.rigs, imuloco.ops.restpose)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from imuloco.app.export import rest_of
from imuloco.core.bodymap import PARTS, resolve_body_map
from imuloco.core.rigs import PRESETS, RIG_NAMES, apply_rig, rebased
from imuloco.errors import UnknownNameError
from imuloco.io.bvh import read_bvh, write_bvh
from imuloco.ops.kinematics import fk
from imuloco.ops.restpose import rebase_offsets, rebase_rotations, rest_globals
from imuloco.ops.rotations import IDENTITY, from_rotvec, qinv, qmul

CLAVICLES = {"bvh-default": "Shoulder_{S}", "mixamo": "mixamorig:{Side}Shoulder",
             "unreal": "clavicle_{s}", "unity": "{Side}Shoulder", "model": "Shoulder_{S}"}


@pytest.fixture(scope="module")
def walk(sample_db):
    return next(c for c in sample_db.clips if "walk" in c.name)


def _rest_positions(sk) -> np.ndarray:
    """Joint positions (J, 3) of a skeleton at rest (every local rotation the identity)."""
    return fk(np.broadcast_to(IDENTITY, (sk.num_joints, 4)), np.zeros(3), sk.offsets,
              sk.parents)[1]


def _shared(names: list[str], name: str) -> list[tuple[str, str]]:
    """(model joint, preset joint) for the joints the presets share: the body parts and the
    clavicles (the model's joint ``names``)."""
    preset = PRESETS.get(name)
    pairs = []
    for side, letter in (("left", "L"), ("right", "R")):
        fill = {"S": letter, "Side": side.capitalize(), "s": letter.lower()}
        pairs.append((CLAVICLES["model"].format(**fill), CLAVICLES[name].format(**fill)))
    for part in PARTS:
        model = resolve_body_map(names)[part]
        if preset is None or preset.parts is None:
            pairs.append((model, model))
        else:
            pairs.append((model, preset.prefix + preset.part_name(part)))
    return pairs


def test_rebasing_on_any_rest_keeps_every_world_position(walk):
    """Any rest pose (here random global rotations) gives the same world positions, and a zero
    local rotation is the rest pose: q' = R_p q R_j^-1, o' = R_p o."""
    sk = walk.skeleton
    rest = from_rotvec(np.random.default_rng(0).normal(size=(sk.num_joints, 3)))
    moved = rebased(walk, rest)
    np.testing.assert_allclose(moved.positions(), walk.positions(), atol=1e-9, rtol=0)
    # the new joint frames are the old ones turned by rest^-1: G' rest = G
    glob, _ = walk.fk()
    new_glob, _ = moved.fk()
    np.testing.assert_allclose(np.abs(np.sum(qmul(new_glob, rest) * glob, axis=-1)), 1.0,
                               atol=1e-9)
    # and the pure functions round-trip: rebasing by rest^-1 gives the originals back
    back = rebase_rotations(moved.rotations, sk.parents, qinv(rest))
    np.testing.assert_allclose(np.abs(np.sum(back * walk.rotations, axis=-1)), 1.0, atol=1e-9)
    np.testing.assert_allclose(rebase_offsets(moved.skeleton.offsets, sk.parents, qinv(rest)),
                               sk.offsets, atol=1e-12)


@pytest.mark.parametrize("name", RIG_NAMES)
def test_presets_keep_the_animation(walk, name):
    """On every preset the joints the presets share (body parts, clavicles) are where they
    were, in every frame, within 1e-6 m (they are the same to rounding: 1e-15)."""
    out = apply_rig(walk, name, rest_of(walk))
    a, b = walk.positions(), out.positions()
    for model, joint in _shared(walk.skeleton.names, name):
        np.testing.assert_allclose(b[:, out.skeleton.index(joint)],
                                   a[:, walk.skeleton.index(model)], atol=1e-6, rtol=0)
    assert out.num_frames == walk.num_frames and out.fps == walk.fps


def _direction(rest: np.ndarray, sk, a: str, b: str) -> np.ndarray:
    v = rest[sk.part(b)] - rest[sk.part(a)]
    return v / np.linalg.norm(v)


def _deg(u: np.ndarray, v) -> float:
    return float(np.degrees(np.arccos(np.clip(np.dot(u, v), -1.0, 1.0))))


@pytest.mark.parametrize("name", ["bvh-default", "mixamo", "unreal", "unity"])
def test_rest_pose_is_a_t_pose(walk, name):
    """At rest (zero local rotations): spine, neck and head up, legs straight down, arms out
    horizontally (left arm along +X), feet forward (+Z): within 3 degrees. The model's own
    rest is not one (every bone along its parent's +X)."""
    out = apply_rig(walk, name, rest_of(walk))
    sk = out.skeleton
    rest = _rest_positions(sk)
    up, down, left, forward = [0, 1, 0], [0, -1, 0], [1, 0, 0], [0, 0, 1]
    for a, b, want in [("spine", "chest", up), ("chest", "neck", up), ("neck", "head", up),
                       *[(f"{s}_{a}", f"{s}_{b}", down) for s in ("left", "right")
                         for a, b in (("hip", "knee"), ("knee", "ankle"))],
                       *[(f"left_{a}", f"left_{b}", left)
                         for a, b in (("shoulder", "elbow"), ("elbow", "wrist"))],
                       *[(f"right_{a}", f"right_{b}", np.negative(left))
                         for a, b in (("shoulder", "elbow"), ("elbow", "wrist"))],
                       ("right_hip", "left_hip", left)]:
        assert _deg(_direction(rest, sk, a, b), want) < 3.0, (name, a, b)
    for side in ("left", "right"):  # the foot points forward, its toe joint lower (flat foot)
        foot = _direction(rest, sk, f"{side}_ankle", f"{side}_toe")
        flat = foot * [1, 0, 1] / np.linalg.norm(foot * [1, 0, 1])
        assert _deg(flat, forward) < 3.0 and foot[1] < 0
    assert rest[sk.part("head"), 1] > rest[sk.part("pelvis"), 1] > rest[sk.part("left_knee"), 1]
    model = _rest_positions(walk.skeleton)
    msk = walk.skeleton
    assert _deg(_direction(model, msk, "left_hip", "left_knee"), down) > 30  # not a T-pose


def test_preset_names_and_hierarchy(walk):
    """Each preset's names and parents as its tool has them; the inserted third spine joint
    is rigid with its parent (its local rotation always zero); the body map finds every part
    on the written BVH (Unreal's names included)."""
    rest = rest_of(walk)
    mixamo = apply_rig(walk, "mixamo", rest)
    sk = mixamo.skeleton

    def parent(s, name):
        return s.names[s.parents[s.index(name)]]

    assert sk.names[0] == "mixamorig:Hips" and all(n.startswith("mixamorig:") for n in sk.names)
    assert parent(sk, "mixamorig:Spine1") == "mixamorig:Spine"
    assert parent(sk, "mixamorig:Spine2") == "mixamorig:Spine1"
    assert parent(sk, "mixamorig:LeftShoulder") == "mixamorig:Spine2"
    assert parent(sk, "mixamorig:LeftArm") == "mixamorig:LeftShoulder"
    assert parent(sk, "mixamorig:LeftToeBase") == "mixamorig:LeftFoot"
    k = sk.index("mixamorig:Spine1")
    assert np.abs(mixamo.rotations[:, k] - IDENTITY).max() == 0
    unreal = apply_rig(walk, "unreal", rest).skeleton
    assert unreal.names[:6] == ["pelvis", "spine_01", "spine_02", "spine_03", "neck_01", "head"]
    assert parent(unreal, "clavicle_l") == "spine_03" and parent(unreal, "ball_r") == "foot_r"
    unity = apply_rig(walk, "unity", rest).skeleton
    assert unity.num_joints == walk.skeleton.num_joints
    assert {"Hips", "Chest", "LeftUpperArm", "RightLowerLeg", "LeftToes"} <= set(unity.names)
    for s in (sk, unreal, unity):
        assert resolve_body_map(s.names) == s.body_map, s.names


@pytest.mark.parametrize("name", ["mixamo", "unreal"])
def test_written_preset_reads_back_to_the_same_motion(walk, tmp_path: Path, name):
    """Through a BVH file (6 decimals of a degree): positions within 1e-5 m, the preset's
    names, and a T-pose rest whose zero pose the reader keeps."""
    out = apply_rig(walk, name, rest_of(walk))
    back = read_bvh(write_bvh(out, tmp_path / f"{name}.bvh"))
    assert back.skeleton.names == out.skeleton.names
    np.testing.assert_allclose(back.positions(), out.positions(), atol=1e-5, rtol=0)
    np.testing.assert_allclose(back.skeleton.offsets, out.skeleton.offsets, atol=1e-7)


def test_rest_globals_and_the_model_preset(walk):
    sk = walk.skeleton
    local = from_rotvec(np.random.default_rng(1).normal(size=(sk.num_joints, 3)))
    glob = rest_globals(local, sk.parents)
    ref, _ = fk(local, np.zeros(3), sk.offsets, sk.parents)
    np.testing.assert_allclose(np.abs(np.sum(glob * ref, axis=-1)), 1.0, atol=1e-9)
    assert apply_rig(walk, "model") is walk
    with pytest.raises(UnknownNameError, match="mixamo"):
        apply_rig(walk, "fbx")
