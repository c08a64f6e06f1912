"""Metrics: zero for identical motions, invariances, and values computed by hand."""

from __future__ import annotations

import numpy as np
import pytest

from imuloco.core.motion import Motion
from imuloco.core.skeleton import Skeleton
from imuloco.measures import metrics
from imuloco.ops.rotations import about_y, from_rotvec, qinv, qmul, qrot


@pytest.fixture(scope="module")
def walk(sample_db) -> Motion:
    return sample_db.where(content="walk").clips[0].slice(0, 90)


def moved(motion: Motion, yaw: float, shift: np.ndarray) -> Motion:
    """The whole motion turned by ``yaw`` about the vertical through the origin, then shifted."""
    q = about_y(np.asarray(yaw))
    rot = motion.rotations.copy()
    rot[:, 0] = qmul(q, rot[:, 0])
    return Motion(motion.skeleton, rot, qrot(q, motion.root) + shift, motion.fps, motion.name)


def with_joint_rotated(motion: Motion, joint: int, rotvec: np.ndarray) -> Motion:
    rot = motion.rotations.copy()
    rot[:, joint] = qmul(rot[:, joint], from_rotvec(np.asarray(rotvec, dtype=float)))
    return Motion(motion.skeleton, rot, motion.root.copy(), motion.fps, motion.name)


def test_identical_motions_give_zero(walk):
    values = metrics.evaluate(walk, walk.copy())
    for key in ("mpjpe_cm", "rmse_cm", "upper_cm", "lower_cm", "angle_deg", "dpv",
                "root_speed_err_cm_s", "path_err_cm"):
        assert values[key] == pytest.approx(0.0, abs=1e-9), key
    assert values["jitter"] == values["jitter_gt"] > 0
    assert values["foot_skate_cm_s"] == values["foot_skate_gt_cm_s"]


def test_rigid_turn_and_shift_are_invisible_to_pose_metrics(walk):
    other = moved(walk, 1.3, np.array([2.0, 0.0, -5.0]))
    assert metrics.mpjpe(walk, other) == pytest.approx(0.0, abs=1e-9)
    assert metrics.rmse(walk, other) == pytest.approx(0.0, abs=1e-9)
    assert metrics.angle_error(walk, other) == pytest.approx(0.0, abs=1e-6)
    # the path error aligns every window's start position and heading
    assert metrics.path_error(walk, other) == pytest.approx(0.0, abs=1e-9)
    assert metrics.root_speed_error(walk, other) == pytest.approx(0.0, abs=1e-9)


def test_dpv_is_translation_invariant_not_rotation_invariant(walk):
    """Tautges et al. 2008 sec. 3.1: 'D_pv is invariant under translation, rotating motions
    yields different results'."""
    assert metrics.dpv(walk, moved(walk, 0.0, np.array([3.0, 0.5, 1.0]))) == pytest.approx(
        0.0, abs=1e-9)
    assert metrics.dpv(walk, moved(walk, 0.5, np.zeros(3))) > 0.1


def test_single_joint_rotation_gives_hand_computed_errors(walk):
    sk = walk.skeleton
    knee = sk.part("right_knee")
    other = with_joint_rotated(walk, knee, [0.0, 0.0, np.radians(30.0)])
    # D_E: one of J joints is off by 30 degrees in every frame
    assert metrics.angle_error(walk, other) == pytest.approx(30.0 / sk.num_joints, rel=1e-9)
    # only the knee's descendants move, each by 2 |lever perpendicular to the axis| sin(15 deg),
    # the lever from the knee expressed in the knee's frame (the axis is its local z)
    grot, pos = walk.fk()
    desc = [j for j in range(sk.num_joints) if _below(sk, j, knee)]
    lever = qrot(qinv(grot[:, knee, None]), pos[:, desc] - pos[:, knee, None])  # (T, D, 3)
    chord = 2 * np.linalg.norm(lever[..., :2], axis=-1) * np.sin(np.radians(15.0))
    expected = chord.sum(axis=1).mean() / (sk.num_joints - 1)
    assert metrics.mpjpe(walk, other) == pytest.approx(expected * 100, rel=1e-6)
    _, lower = metrics.body_halves(sk)
    assert metrics.mpjpe(walk, other, "upper") == pytest.approx(0.0, abs=1e-9)
    assert metrics.mpjpe(walk, other, "lower") == pytest.approx(
        expected * 100 * (sk.num_joints - 1) / len(lower), rel=1e-6)


def _below(sk: Skeleton, j: int, ancestor: int) -> bool:
    """Whether joint j is a strict descendant of ``ancestor``."""
    while j > ancestor:
        j = int(sk.parents[j])
        if j == ancestor:
            return True
    return False


def test_rmse_and_mpjpe_by_hand():
    """A 3-joint chain rotated at its middle joint: the tip moves by a known distance."""
    sk = Skeleton(["root", "l", "r", "mid", "tip"], np.array([-1, 0, 0, 0, 3]),
                  np.array([[0, 0, 0], [0.1, 0, 0], [-0.1, 0, 0], [0, 0.3, 0], [0, 0.4, 0]]),
                  body_map={"pelvis": "root", "left_hip": "l", "right_hip": "r"})
    rot = np.zeros((5, 5, 4))
    rot[..., 3] = 1.0
    gt = Motion(sk, rot, np.zeros((5, 3)), 30.0)
    other = with_joint_rotated(gt, 3, [np.radians(90.0), 0, 0])  # tip 0.4 m swings 90 deg
    d = 0.4 * np.sqrt(2.0)
    assert metrics.mpjpe(gt, other) == pytest.approx(d / 4 * 100)
    assert metrics.rmse(gt, other) == pytest.approx(np.sqrt(d**2 / 4) * 100)
    assert metrics.angle_error(gt, other) == pytest.approx(90.0 / 5)


def test_dpv_by_hand():
    """One joint with two children; motion 2's child a is turned so the cross product changes.

    Motion 1: v_a = (1, 0, 0), v_b = (0, 1, 0) -> c1 = (0, 0, 1), constant.
    Motion 2: v_a = (0, 0, 1) -> c2 = (0, 0, 1) x ... = v_a x v_b = (-1, 0, 0), constant.
    C = |c1 - c2| = sqrt(2) per frame, Cdot = 0 (both constant); two ordered pairs (a, b) and
    (b, a) with the same |C|: D_pv = sqrt(T * 2 * 2).
    """
    t = 7
    parents = np.array([-1, 0, 0])
    p1 = np.tile(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]]), (t, 1, 1))
    p2 = np.tile(np.array([[0, 0, 0], [0, 0, 1], [0, 1, 0.0]]), (t, 1, 1))
    assert metrics.dpv_positions(p1, p2, parents) == pytest.approx(np.sqrt(t * 2 * 2))


def test_dpv_velocity_term_by_hand():
    """Same pose, different motion: child a spins in motion 2 only.

    c1 constant (0, 0, 1); in motion 2 c2 = c1 at frame f0 but its derivative is nonzero:
    at that frame C = 0 and Cdot = |v_a||v_b| |c2'| / |c2'| = |v_a||v_b| = 1 (eq. 14).
    """
    t = 5
    parents = np.array([-1, 0, 0])
    p1 = np.tile(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]]), (t, 1, 1))
    ang = (np.arange(t) - 2) * 0.1  # a turns about y; at frame 2 both poses coincide
    p2 = p1.copy()
    p2[:, 1] = np.stack([np.cos(ang), np.zeros(t), -np.sin(ang)], axis=1)
    c2 = np.cross(p2[:, 1], p2[:, 2])
    c1 = np.cross(p1[:, 1], p1[:, 2])
    d2 = np.gradient(c2, axis=0)
    big_c = np.linalg.norm(c1 - c2, axis=1)
    dot = np.linalg.norm(d2, axis=1) / np.linalg.norm(d2, axis=1)  # |v_a||v_b| = 1
    expected = np.sqrt(2 * ((big_c + dot) ** 2).sum())
    assert big_c[2] == pytest.approx(0.0)
    assert metrics.dpv_positions(p1, p2, parents) == pytest.approx(expected)


def test_dpv_ignores_joints_with_one_child(two_joint_skeleton, spinning_motion):
    other = with_joint_rotated(spinning_motion, 0, [0.5, 0, 0])
    p1, p2 = spinning_motion.positions(), other.positions()
    assert metrics.dpv_positions(p1, p2, two_joint_skeleton.parents) == 0.0


def test_jitter_of_constant_velocity_is_zero_and_of_a_parabola_too(walk):
    t = np.arange(60) / 30.0
    rot = np.repeat(walk.rotations[:1], 60, axis=0)
    lin = Motion(walk.skeleton, rot, np.outer(t, [1.2, 0.0, 0.3]) + walk.root[0], 30.0)
    assert metrics.jitter(lin) == pytest.approx(0.0, abs=1e-6)
    acc = Motion(walk.skeleton, rot, np.outer(t**2, [1.0, 0, 0]) + walk.root[0], 30.0)
    assert metrics.jitter(acc) == pytest.approx(0.0, abs=1e-6)
    cubic = Motion(walk.skeleton, rot, np.outer(t**3, [1.0, 0, 0]) + walk.root[0], 30.0)
    assert metrics.jitter(cubic) == pytest.approx(6.0, rel=1e-6)  # d3(t^3)/dt3 = 6 m/s^3


def test_foot_skate_measures_sliding_feet(walk):
    """A reconstruction that glides at 1 m/s slides every planted foot by 100 cm/s more."""
    t = walk.times
    slide = Motion(walk.skeleton, walk.rotations, walk.root + np.outer(t, [0, 0, 1.0]),
                   walk.fps)
    contacts = {k: np.ones(walk.num_frames, dtype=bool) for k in
                ("left_heel", "left_toe", "right_heel", "right_toe")}
    still = Motion(walk.skeleton, np.repeat(walk.rotations[:1], len(t), 0),
                   np.repeat(walk.root[:1], len(t), 0), walk.fps)
    moving = Motion(walk.skeleton, still.rotations, still.root + np.outer(t, [0, 0, 1.0]),
                    walk.fps)
    assert metrics.foot_skate(walk, still, contacts) == pytest.approx(0.0, abs=1e-9)
    assert metrics.foot_skate(walk, moving, contacts) == pytest.approx(100.0, rel=1e-9)
    assert metrics.foot_skate(walk, slide) > metrics.foot_skate(walk, walk) + 50.0


def test_root_speed_and_path_errors_by_hand(walk):
    """A standing reconstruction of a motion walking straight at 1 m/s: speed error 100 cm/s;
    in each 2 s window the mean distance is the mean of 1 m/s * t over t in [0, 2] s = 100 cm."""
    n = 121  # 4 s at 30 fps: two full windows
    t = np.arange(n) / 30.0
    rot = np.repeat(walk.rotations[:1], n, axis=0)
    theta = metrics.heading_of(Motion(walk.skeleton, rot[:1], walk.root[:1], 30.0))[0]
    fwd = np.array([np.sin(theta), 0.0, np.cos(theta)])
    gt = Motion(walk.skeleton, rot, walk.root[0] + np.outer(t, fwd), 30.0)
    rec = Motion(walk.skeleton, rot, np.repeat(walk.root[:1], n, axis=0), 30.0)
    assert metrics.time_windows(n, 30.0) == [(0, 60), (60, 120)]
    assert metrics.root_speed_error(gt, rec) == pytest.approx(100.0)
    assert metrics.path_error(gt, rec) == pytest.approx(100.0)
    # walking at the right speed but 90 degrees off the heading: speed fine, path wrong
    side = np.array([fwd[2], 0.0, -fwd[0]])
    wrong = Motion(walk.skeleton, rot, walk.root[0] + np.outer(t, side), 30.0)
    assert metrics.root_speed_error(gt, wrong) == pytest.approx(0.0, abs=1e-9)
    assert metrics.path_error(gt, wrong) == pytest.approx(np.sqrt(2) * 100.0)


def test_align_heading_matches_start(walk):
    other = moved(walk, 2.0, np.array([1.0, 0.0, 4.0]))
    back = metrics.align_heading(other, walk)
    assert np.allclose(back.positions(), walk.positions(), atol=1e-9)


def test_body_halves_cover_every_joint_but_the_root(walk):
    upper, lower = metrics.body_halves(walk.skeleton)
    names = walk.skeleton.names
    assert sorted([*upper, *lower]) == list(range(1, len(names)))
    assert {names[j] for j in lower} == {f"{p}_{s}" for s in "LR" for p in
                                         ("UpperLeg", "LowerLeg", "Foot", "Toes")}


def test_mismatched_pairs_fail_clearly(walk, spinning_motion):
    with pytest.raises(ValueError, match="length"):
        metrics.mpjpe(walk, walk.slice(0, 10))
    with pytest.raises(ValueError, match="skeleton"):
        metrics.evaluate(walk.slice(0, 90), spinning_motion)


def test_evaluate_files(tmp_path, walk):
    from imuloco.io.bvh import write_bvh

    write_bvh(walk, tmp_path / "gt.bvh")
    write_bvh(walk.slice(0, 60), tmp_path / "rec.bvh")
    values, note = metrics.evaluate_files(tmp_path / "gt.bvh", tmp_path / "rec.bvh")
    assert "60" in note
    assert values["mpjpe_cm"] == pytest.approx(0.0, abs=1e-3)


def test_evaluate_files_of_other_rigs_name_the_first_difference(tmp_path, walk,
                                                                 spinning_motion):
    """Two rigs: the error gives the joint counts and the first joint that differs, not every
    joint name of both (a 101-joint CMU rig made it 1,700 characters)."""
    from imuloco.errors import InputError
    from imuloco.io.bvh import write_bvh

    write_bvh(walk, tmp_path / "gt.bvh")
    write_bvh(spinning_motion, tmp_path / "rec.bvh")
    a, b = walk.skeleton.names, spinning_motion.skeleton.names
    with pytest.raises(InputError) as e:
        metrics.evaluate_files(tmp_path / "gt.bvh", tmp_path / "rec.bvh")
    k = next(i for i, (x, y) in enumerate(zip(b, a)) if x != y)
    assert f"{len(b)} joints against {len(a)}; joint {k} is {b[k]!r}" in str(e.value)
    assert str(list(a)) not in str(e.value) and str(list(b)) not in str(e.value)
