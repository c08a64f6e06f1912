"""The per-part fallback toward neutral poses (imuloco.methods.fallback) on constructed inputs."""

import numpy as np
import pytest

from imuloco.errors import ModelFileError
from imuloco.measures.strides import stride_rows
from imuloco.methods.base import Reconstruction
from imuloco.methods.fallback import (
    GROUPS,
    FallbackRule,
    NeutralPoses,
    apply_fallback,
    joint_groups,
    position_groups,
    shipped_neutral,
)
from imuloco.methods.training import synthesize
from imuloco.ops.rotations import geodesic


@pytest.fixture(scope="module")
def walk(sample_db):
    """A walking clip of the sample with its virtual right-shin phone."""
    i = next(i for i, lab in enumerate(sample_db.labels) if lab.get("content") == "walk")
    return synthesize(sample_db.subset([i]), ["right_ankle"], "phone", 3)[0]


@pytest.fixture(scope="module")
def neutral():
    return shipped_neutral()


def still_signals(n: int, seed: int = 0) -> np.ndarray:
    """A phone lying still on a standing shin: gravity up the shin, sensor noise only."""
    rng = np.random.default_rng(seed)
    s = rng.normal(0.0, [0.05, 0.05, 0.05, 0.01, 0.01, 0.01], (n, 6))
    s[:, 1] += 9.81
    return s


def group_joints(motion, group: str) -> np.ndarray:
    return np.flatnonzero(joint_groups(motion.skeleton) == GROUPS.index(group))


def test_joint_groups_of_the_bandai_skeleton(walk):
    sk = walk.motion.skeleton
    rot = joint_groups(sk)
    name = dict(zip(sk.names, rot))
    assert name["Hips"] == -1
    assert [GROUPS[name[n]] for n in ("UpperLeg_R", "Foot_L", "Toes_R")] == ["legs"] * 3
    assert [GROUPS[name[n]] for n in ("Shoulder_L", "UpperArm_R", "Hand_L")] == ["arms"] * 3
    assert [GROUPS[name[n]] for n in ("Spine", "Chest", "Neck", "Head")] == ["trunk"] * 4
    pos = dict(zip(sk.names, position_groups(sk)))
    # a knee's position follows the hip joint's rotation; the hips' the pelvis's (with the legs)
    assert GROUPS[pos["LowerLeg_L"]] == "legs" and GROUPS[pos["UpperLeg_L"]] == "legs"
    assert GROUPS[pos["UpperArm_R"]] == "arms" and GROUPS[pos["Shoulder_R"]] == "trunk"


def test_a_still_sensor_gives_the_standing_pose_and_no_strides(walk, neutral):
    """A walking reconstruction over a sensor that lies still: every part takes the standing
    pose, the root stops, and no stride is left."""
    assert len(stride_rows(walk.motion)) > 0  # the model's walk has strides
    n = walk.motion.num_frames
    out, report = apply_fallback(Reconstruction(walk.motion, np.full(n, 0.05),
                                                 np.zeros(n, bool)),
                                 still_signals(n), "right_ankle", neutral)
    m = out.motion
    stand = neutral.on(m.skeleton)[0]
    joints = np.flatnonzero(joint_groups(m.skeleton) >= 0)
    assert geodesic(m.rotations[:, joints], stand[joints]).max() < 1e-6
    # the root stands (it only turns with the walk's heading, the feet held where they stand)
    assert np.ptp(walk.motion.root[:, [0, 2]], axis=0).max() > 1.0
    assert np.ptp(m.root[:, [0, 2]], axis=0).max() < 0.03
    assert len(stride_rows(m)) == 0
    feet = m.part_positions(["left_ankle", "left_toe", "right_ankle", "right_toe"])
    assert feet[..., 1].min(axis=1) == pytest.approx(neutral.clearance_m, abs=1e-9)
    # the predicted error rises to the standing pose's expected error, the unseen parts flagged
    assert out.error_m.min() >= np.sqrt(neutral.sq_error_m2[0].sum()) - 1e-12
    assert out.unreliable.all()
    j = report.to_json()
    assert j["enabled"] and j["acted"] and j["still_fraction"] == 1.0
    assert j["frames_fraction"] == {"legs": 1.0, "arms": 1.0, "trunk": 1.0}
    assert j["observes"] == ["legs"]


def test_a_walking_signal_leaves_the_walk_untouched(walk, neutral):
    """Familiar motion (no novelty score: a method without one) over a walking sensor: the
    motion is the method's to 1 mm, its confidence unchanged."""
    n = walk.motion.num_frames
    err = np.full(n, 0.05)
    out, report = apply_fallback(Reconstruction(walk.motion, err, np.zeros(n, bool)),
                                 walk.signals, "right_ankle", neutral)
    assert np.abs(out.motion.positions() - walk.motion.positions()).max() < 1e-3
    assert np.array_equal(out.error_m, err) and not out.unreliable.any()
    assert not report.acted


def test_unseen_parts_under_high_novelty_move_to_neutral(walk, neutral):
    """An unfamiliar motion (novelty 10) over a walking sensor: the arms and trunk take the
    walking neutral pose, the legs the shin sees stay the model's; the predicted error rises
    to at least what the neutral arms and trunk miss, and the frames are flagged."""
    n = walk.motion.num_frames
    full = Reconstruction(walk.motion, np.full(n, 0.01), np.zeros(n, bool),
                          scores={"novelty": np.full(n, 10.0)})
    out, report = apply_fallback(full, walk.signals, "right_ankle", neutral)
    m, moving = out.motion, neutral.on(walk.motion.skeleton)[1]
    for g in ("arms", "trunk"):
        j = group_joints(m, g)
        assert geodesic(m.rotations[:, j], moving[j]).max() < 1e-6
    legs = group_joints(m, "legs")
    assert geodesic(m.rotations[:, legs], walk.motion.rotations[:, legs]).max() < 1e-6
    floor = np.sqrt(neutral.sq_error_m2[1][[GROUPS.index("arms"), GROUPS.index("trunk")]]
                    .sum())
    assert out.error_m.min() >= floor - 1e-12 > 0.01
    assert out.unreliable.all()
    assert report.to_json()["frames_fraction"] == {"legs": 0.0, "arms": 1.0, "trunk": 1.0}


def test_the_weights_are_smooth_in_the_evidence():
    rule = FallbackRule()
    x = np.linspace(0.0, 6.0, 601)
    w = rule.novel(x, len(x))
    assert w[x <= rule.novelty_low].max() == 0 and w[x >= rule.novelty_high].min() == 1
    assert np.all(np.diff(w) >= 0) and np.abs(np.diff(w)).max() < 0.02  # no jump
    assert np.array_equal(rule.novel(None, 5), np.zeros(5))


def test_neutral_poses_round_trip_and_refuse_other_files(tmp_path, neutral):
    path = neutral.save(tmp_path / "n.npz")
    back = NeutralPoses.load(path)
    assert back.names == neutral.names and np.array_equal(back.rotations, neutral.rotations)
    assert back.clearance_m == neutral.clearance_m and "CC BY-NC" in back.source
    np.savez(tmp_path / "other.npz", x=np.zeros(3))
    with pytest.raises(ModelFileError, match="other.npz"):
        NeutralPoses.load(tmp_path / "other.npz")


def test_the_shipped_neutral_fits_the_shipped_models(neutral):
    """Every shipped model's joints (its file's JSON header, read without loading the model)
    have a neutral rotation."""
    import json

    from imuloco.app.pipeline import shipped_model, shipped_placements

    for placement in shipped_placements():
        with np.load(shipped_model("learned", placement), allow_pickle=False) as z:
            names = json.loads(z["__header__"].tobytes().decode("utf-8"))["skeleton"]["names"]
        assert len(names) == 21 and set(names) <= set(neutral.names)


def test_switched_off_the_pipeline_gives_the_methods_output(sample_db,
                                                            ridge_without_demo_clip):
    """``fallback=False``: the motion and confidence are those of the method, pinned, as
    before the fallback existed; on, the report says what it did."""
    from imuloco.app.pipeline import calibrated, reconstruct_recording
    from imuloco.methods.postprocess import pin_detected_contacts
    from imuloco.sensors.simulate import simulate

    method = ridge_without_demo_clip
    rec = simulate(sample_db.clips[0], ["right_ankle"], rate=100.0, noise="phone", seed=5)
    off, info = reconstruct_recording(rec, method, fallback=False)
    want = pin_detected_contacts(method.reconstruct_full(calibrated(rec)[0]).motion)
    assert np.array_equal(off.rotations, want.rotations)
    assert np.array_equal(off.root, want.root)
    assert info["fallback"].to_json()["enabled"] is False
    _on, info = reconstruct_recording(rec, method)
    assert info["fallback"].to_json()["enabled"] is True


def test_cli_no_fallback_is_in_the_report(tmp_path, sample_db, ridge_without_demo_clip):
    import json

    from click.testing import CliRunner

    from imuloco.cli import cli
    from imuloco.io.sensorlog import write_generic_csv
    from imuloco.sensors.simulate import simulate

    rec = simulate(sample_db.clips[0].slice(0, 120), ["right_ankle"], 100.0, "phone", seed=5)
    log = write_generic_csv(rec, tmp_path / "walk.csv")
    model = ridge_without_demo_clip.save(tmp_path / "r.npz")
    for flag, enabled in (["--no-fallback"], False), ([], True):
        report = tmp_path / f"r{enabled}.json"
        result = CliRunner().invoke(cli, ["reconstruct", str(log), "--model", str(model), "-o",
                                          str(tmp_path / f"m{enabled}.bvh"), "--report",
                                          str(report), *flag])
        assert result.exit_code == 0, result.output
        assert json.loads(report.read_text())["fallback"]["enabled"] is enabled
