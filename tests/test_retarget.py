"""Retargeting by body part (core.retarget), the body map of other rigs, several data folders
as one training set, and --skeleton RIG.bvh."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.spatial.transform import Rotation

from imuloco.cli import cli
from imuloco.core.bodymap import PARTS, BodyMapError, resolve_body_map
from imuloco.core.motion import Motion
from imuloco.core.retarget import Rig, resampled, retarget
from imuloco.core.skeleton import Skeleton
from imuloco.io.bvh import write_bvh
from imuloco.io.database import load_sample
from imuloco.ops.rotations import geodesic, qinv, qmul, qrot
from imuloco.phases.contacts import flat_foot_pitch, foot_contacts, foot_pitches

# the sample's joints under Mixamo's names (its clavicles are "Shoulder", its chest "Spine1")
MIXAMO = {"Hips": "Hips", "Spine": "Spine", "Chest": "Spine1", "Neck": "Neck", "Head": "Head",
          **{f"{bn}_{s[0]}": f"{s}{mx}" for s in ("Left", "Right")
             for bn, mx in (("Shoulder", "Shoulder"), ("UpperArm", "Arm"),
                            ("LowerArm", "ForeArm"), ("Hand", "Hand"), ("UpperLeg", "UpLeg"),
                            ("LowerLeg", "Leg"), ("Foot", "Foot"), ("Toes", "ToeBase"))}}


@pytest.fixture(scope="module")
def clip() -> Motion:
    db = load_sample()
    return next(c for c in db.clips if c.name == "dataset-2_walk_normal_001")


def other_rig(motion: Motion, scale: float = 1.1, seed: int = 1) -> Motion:
    """The same movement on a Mixamo-named rig whose joint frames are turned at random (as
    another exporter's are) and whose bones are ``scale`` times longer."""
    sk = motion.skeleton
    q = Rotation.random(sk.num_joints, random_state=seed).as_quat()
    q[0] = [0.0, 0.0, 0.0, 1.0]
    qp = np.array([q[p] if p >= 0 else [0.0, 0.0, 0.0, 1.0] for p in sk.parents])
    names = ["mixamorig:" + MIXAMO[n] for n in sk.names]
    rig = Skeleton(names, sk.parents, qrot(qinv(qp), sk.offsets) * scale)
    rot = qmul(qmul(qinv(qp)[None], motion.rotations), q[None])
    return Motion(rig, rot, motion.root * scale, motion.fps, motion.name)


def part_globals(m: Motion) -> np.ndarray:
    return m.fk()[0][:, [m.skeleton.part(p) for p in PARTS]]


def test_bodymap_maps_character_creator_names_and_ignores_extra_bones():
    names = ["RL_BoneRoot", "CC_Base_Hip", "CC_Base_Pelvis", "CC_Base_Waist", "CC_Base_Spine01",
             "CC_Base_Spine02", "CC_Base_NeckTwist01", "CC_Base_NeckTwist02", "CC_Base_Head",
             "CC_Base_FacialBone", "CC_Base_JawRoot"]
    for s in "LR":
        names += [f"CC_Base_{s}_{b}" for b in (
            "Thigh", "ThighTwist01", "Calf", "CalfTwist01", "KneeShareBone", "Foot",
            "ToeBaseShareBone", "ToeBase", "BigToe1", "Clavicle", "Upperarm", "UpperarmTwist01",
            "Forearm", "ForearmTwist01", "ElbowShareBone", "Hand", "Index1", "Thumb1")]
    bm = resolve_body_map(names)
    assert set(bm) == set(PARTS)
    assert bm["pelvis"] == "CC_Base_Hip" and bm["neck"] == "CC_Base_NeckTwist01"
    assert bm["left_knee"] == "CC_Base_L_Calf" and bm["right_toe"] == "CC_Base_R_ToeBase"
    assert bm["left_shoulder"] == "CC_Base_L_Upperarm" and bm["right_wrist"] == "CC_Base_R_Hand"
    # CC's neck is a "twist" bone by name; no other twist, share, toe or finger bone is used
    assert not any(k in j for p, j in bm.items() if p != "neck"
                   for k in ("Twist", "Share", "Toe1", "Index", "Thumb"))


def test_onto_its_own_skeleton_nothing_changes(clip):
    out = retarget(clip, Rig.measure([clip]))
    assert out.skeleton is clip.skeleton
    np.testing.assert_allclose(out.rotations, clip.rotations, atol=1e-12)
    np.testing.assert_allclose(out.root, clip.root, atol=1e-12)


def test_onto_a_scaled_skeleton_angles_stay_and_the_root_path_scales(clip):
    big = clip.skeleton.scaled(1.3)
    out = retarget(clip, big)
    np.testing.assert_allclose(out.rotations, clip.rotations, atol=1e-12)
    np.testing.assert_allclose(out.root, 1.3 * clip.root, atol=1e-9)
    np.testing.assert_allclose(out.positions(), 1.3 * clip.positions(), atol=1e-9)


def test_onto_another_rig_and_back_body_part_rotations_are_kept(clip):
    mixamo = other_rig(clip)
    rig = Rig.measure([mixamo])
    out = retarget(clip, rig)
    assert out.skeleton is mixamo.skeleton
    # the rig measured in the same movement: its parts turn exactly as the source's
    assert np.degrees(geodesic(part_globals(out), part_globals(mixamo))).max() < 1e-6
    # root path scaled by the leg lengths' ratio, feet on the floor where they were
    pel = out.part_positions(["pelvis"])[:, 0]
    np.testing.assert_allclose(pel[:, [0, 2]], 1.1 * clip.root[:, [0, 2]], atol=1e-6)
    back = retarget(out, Rig.measure([clip]), rig)
    assert np.degrees(geodesic(part_globals(back), part_globals(clip))).max() < 1e-6
    # joints without a part (clavicles) take the rig's mean pose: positions stay within cm
    assert np.abs(back.positions() - clip.positions()).max() < 0.05


def test_a_rig_that_cannot_be_mapped_is_refused_naming_its_parts(clip):
    sk = clip.skeleton
    names = [n if n not in ("Foot_L", "Hand_R") else f"bone{i}" for i, n in enumerate(sk.names)]
    bad = Motion(Skeleton(names, sk.parents, sk.offsets), clip.rotations, clip.root, clip.fps,
                 "odd.bvh")
    with pytest.raises(BodyMapError, match=r"odd\.bvh.*left_ankle.*right_wrist"):
        Rig.measure([bad])
    with pytest.raises(BodyMapError, match="left_ankle"):
        retarget(bad, Rig.measure([clip]))


def test_resampled_keeps_the_motion_at_another_rate(clip):
    fast = resampled(clip, 60.0)
    assert fast.fps == 60.0 and fast.num_frames == 2 * clip.num_frames - 1
    np.testing.assert_allclose(fast.root[::2], clip.root, atol=1e-12)
    assert np.degrees(geodesic(fast.rotations[::2], clip.rotations)).max() < 1e-6
    back = resampled(fast, 30.0)
    assert back.num_frames == clip.num_frames


def test_skeleton_option_writes_the_motion_on_the_users_rig(clip, tmp_path):
    from imuloco.io.bvh import read_bvh
    from imuloco.io.sensorlog import write_generic_csv
    from imuloco.sensors.simulate import simulate

    rig_file = write_bvh(other_rig(clip, 1.2), tmp_path / "mixamo.bvh")
    rec = simulate(clip, ["right_ankle"], rate=100.0, noise="phone", seed=3)
    write_generic_csv(rec, tmp_path / "rec.csv")
    runner = CliRunner()
    res = runner.invoke(cli, ["reconstruct", str(tmp_path / "rec.csv"), "--method", "mean",
                              "-o", str(tmp_path / "plain.bvh")])
    assert res.exit_code == 0, res.output
    res = runner.invoke(cli, ["reconstruct", str(tmp_path / "rec.csv"), "--method", "mean",
                              "--skeleton", str(rig_file), "-o", str(tmp_path / "out.bvh")])
    assert res.exit_code == 0, res.output
    plain, out = read_bvh(tmp_path / "plain.bvh"), read_bvh(tmp_path / "out.bvh")
    rig = read_bvh(rig_file)
    assert out.skeleton.names == rig.skeleton.names
    np.testing.assert_allclose(out.skeleton.offsets, rig.skeleton.offsets, atol=1e-6)
    assert out.num_frames == plain.num_frames
    # every segment points the same way, the path is 1.2 times as long, the feet on the floor
    for a, b in (("left_hip", "left_knee"), ("right_knee", "right_ankle"), ("chest", "neck"),
                 ("left_shoulder", "left_elbow"), ("right_elbow", "right_wrist")):
        d = [np.diff(m.part_positions([a, b]), axis=1)[:, 0] for m in (plain, out)]
        cos = np.sum(d[0] * d[1], axis=-1) / np.prod(np.linalg.norm(d, axis=-1), axis=0)
        assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 0.1
    path = [np.linalg.norm(np.diff(m.root[:, [0, 2]], axis=0), axis=1).sum() for m in (plain, out)]
    assert path[1] == pytest.approx(1.2 * path[0], rel=0.02)
    feet = ["left_ankle", "left_toe", "right_ankle", "right_toe"]
    floor = [np.percentile(m.part_positions(feet)[..., 1].min(axis=1), 5) for m in (plain, out)]
    assert floor[1] == pytest.approx(1.2 * floor[0], abs=0.005)
    # a rig without feet is refused, naming what it lacks
    bad = other_rig(clip)
    names = [n.replace("LeftFoot", "LeftPaw") for n in bad.skeleton.names]
    bad = Motion(Skeleton(names, bad.skeleton.parents, bad.skeleton.offsets), bad.rotations,
                 bad.root, bad.fps)
    write_bvh(bad, tmp_path / "paw.bvh")
    res = runner.invoke(cli, ["reconstruct", str(tmp_path / "rec.csv"), "--method", "mean",
                              "--skeleton", str(tmp_path / "paw.bvh"),
                              "-o", str(tmp_path / "x.bvh")])
    assert res.exit_code != 0 and "paw.bvh" in res.output and "left_ankle" in res.output
    assert not (tmp_path / "x.bvh").exists()


@pytest.mark.shared
def test_the_character_creator_rig_of_cmu_iclone(shared_dir, clip):
    """Every part maps on the 101-joint CC rig; a clip goes onto it and back with its
    body-part rotations; a CC clip retargeted onto the Bandai-Namco skeleton keeps its legs."""
    from imuloco.io.database import load_database
    from imuloco.measures.metrics import evaluate_parts, part_errors

    cc = load_database(shared_dir.parent / "cmu-iclone", limit=2, progress=False)
    assert cc.skeleton.num_joints > 90 and set(cc.skeleton.body_map) == set(PARTS)
    assert {"content", "subject", "description"} <= set(cc.labels[0])
    rig = Rig.measure(cc.clips[:1])
    on_cc = retarget(clip, rig)
    assert on_cc.skeleton.names == cc.skeleton.names
    back = retarget(on_cc, Rig.measure([clip]), rig)
    assert np.degrees(geodesic(part_globals(back), part_globals(clip))).max() < 1e-6
    walk = resampled(cc.clips[0], clip.fps)
    bandai = Rig.measure([clip])
    onto_bandai = retarget(walk, bandai)
    err = part_errors(walk, onto_bandai)[0].mean(axis=0)  # other proportions: legs within 3 cm
    legs = [PARTS.index(f"{s}_{j}") for s in ("left", "right") for j in ("hip", "knee", "ankle")]
    assert err[legs].max() < 0.03 and evaluate_parts(walk, onto_bandai)["mpjpe_cm"] < 10.0
    # CC's toe joint sits inside the foot, 13 degrees below its ankle joint when the foot is
    # flat; Bandai-Namco's at the sole, 40 below: a flat CC foot stands flat on Bandai-Namco
    assert np.degrees(Rig.measure([walk]).foot_pitch) == pytest.approx(-13, abs=3)
    assert flat_foot_pitch([onto_bandai]) == pytest.approx(bandai.foot_pitch, abs=np.radians(2))


def test_a_flat_foot_stays_flat_on_a_rig_whose_toe_joint_sits_elsewhere(clip):
    """Rigs put the toe joint at other places on the foot: the ankle-to-toe direction is not
    copied, the foot's orientation on the floor is."""
    sk = clip.skeleton
    c = foot_contacts(clip)
    glob, pos = clip.fk()
    offsets = sk.offsets.copy()
    for s in ("left", "right"):  # each toe joint moved up to 15 degrees below its ankle joint
        ankle, toe = sk.part(f"{s}_ankle"), sk.part(f"{s}_toe")
        t = int(np.flatnonzero(c[f"{s}_heel"] & c[f"{s}_toe"])[0])  # a flat foot
        d = pos[t, toe] - pos[t, ankle]
        raised = np.array([d[0], np.tan(np.radians(-15.0)) * np.hypot(d[0], d[2]), d[2]])
        offsets[toe] = qrot(qinv(glob[t, ankle]), raised)
    high = other_rig(Motion(Skeleton(sk.names, sk.parents, offsets), clip.rotations, clip.root,
                            clip.fps), scale=1.0)  # and other joint frames: another family
    rig = Rig.measure([high])
    assert np.degrees(rig.foot_pitch) == pytest.approx(-15, abs=2)
    assert np.degrees(Rig.measure([clip]).foot_pitch) == pytest.approx(-40, abs=2)
    out = retarget(clip, rig)
    # the foot turns as the source's: its toe joint 25 degrees higher in every frame
    lift = foot_pitches(out.skeleton, out.positions()) - foot_pitches(sk, pos)
    assert np.degrees(np.median(np.abs(lift - np.radians(25)))) < 3.0  # copying the direction: 25
    assert flat_foot_pitch([out]) == pytest.approx(rig.foot_pitch, abs=np.radians(2))


def test_batch_refuses_an_unmappable_rig_before_any_work(clip, tmp_path):
    from imuloco.app.batch import run_batch

    sk = clip.skeleton
    names = [n.replace("Head", "Skull") for n in sk.names]
    write_bvh(Motion(Skeleton(names, sk.parents, sk.offsets), clip.rotations, clip.root,
                     clip.fps), tmp_path / "nohead.bvh")
    (tmp_path / "rec.csv").write_text("time_s,acc_x,acc_y,acc_z,gyro_x,gyro_y,gyro_z\n")
    with pytest.raises(BodyMapError, match=r"nohead\.bvh.*'head'"):
        run_batch([tmp_path / "rec.csv"], tmp_path / "out", skeleton=tmp_path / "nohead.bvh")
    assert not (tmp_path / "out").exists()
