"""The per-part fallback toward neutral poses (imuloco.methods.fallback) on constructed inputs."""

import numpy as np
import pytest

from imuloco.errors import ModelFileError
from imuloco.measures.strides import stride_rows
from imuloco.methods.base import Reconstruction
from imuloco.methods.fallback import (
    GROUPS,
    FallbackRule,
    FallbackStream,
    NeutralPoses,
    apply_fallback,
    fallback_recording,
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
    """An unfamiliar motion (novelty 10, the threshold 3.6) over a walking sensor: the arms and trunk take the
    walking neutral pose, the legs the shin sees stay the model's; the predicted error rises
    to at least what the neutral arms and trunk miss, and the frames are flagged."""
    n = walk.motion.num_frames
    full = Reconstruction(walk.motion, np.full(n, 0.01), np.zeros(n, bool),
                          scores={"novelty": np.full(n, 10.0)})
    out, report = apply_fallback(full, walk.signals, "right_ankle", neutral,
                                 novelty_threshold=3.6)
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
    w = rule.novel(x, len(x), 3.0)
    assert w[x <= 3.0 * rule.novelty_start].max() == 0
    assert w[x >= 3.0 * rule.novelty_full].min() == 1
    assert np.all(np.diff(w) >= 0) and np.abs(np.diff(w)).max() < 0.02  # no jump
    assert np.array_equal(rule.novel(None, 5, 3.0), np.zeros(5))
    assert np.array_equal(rule.novel(x, len(x), None), np.zeros(len(x)))  # no scale: no say


def _arms_moved(out, walk, neutral) -> float:
    """The largest angle (radians) between the arms' rotations of ``out`` and the walking
    neutral pose's."""
    j = group_joints(out.motion, "arms")
    return float(geodesic(out.motion.rotations[:, j], neutral.on(walk.motion.skeleton)[1][j])
                 .max())


def test_novelty_is_judged_on_the_methods_own_scale(walk, neutral):
    """The same novelty score (5.0) is far beyond a method's flag threshold of 2.5 (the
    arms take the walking neutral pose) and under one of 10 (the model's arms stay): the
    range follows the method's threshold, not the shipped shin model's 3.62 (which would
    hold the arms 90 % of the way at 5.0 with a threshold of 10, and 90 %, not all the way,
    with 2.5)."""
    n = walk.motion.num_frames
    full = Reconstruction(walk.motion, np.full(n, 0.01), np.zeros(n, bool),
                          scores={"novelty": np.full(n, 5.0)})
    low, _ = apply_fallback(full, walk.signals, "right_ankle", neutral, novelty_threshold=2.5)
    assert _arms_moved(low, walk, neutral) < 1e-6 and low.unreliable.all()
    high, report = apply_fallback(full, walk.signals, "right_ankle", neutral,
                                  novelty_threshold=10.0)
    j = group_joints(walk.motion, "arms")
    assert geodesic(high.motion.rotations[:, j], walk.motion.rotations[:, j]).max() < 1e-6
    assert not high.unreliable.any() and not report.acted


def test_the_pipeline_reads_the_threshold_from_the_method(walk, neutral):
    """:func:`fallback_recording` judges the novelty on the method's own
    ``novelty_threshold``; the shipped learned model's is its file's."""
    from types import SimpleNamespace

    from imuloco.app.pipeline import shipped_model
    from imuloco.core.recording import Recording
    from imuloco.methods import load_model

    n, fps = walk.motion.num_frames, walk.motion.fps
    sig = walk.signals
    rec = Recording(np.arange(n) / fps, sig[:, None, :3], sig[:, None, 3:], ["right_ankle"])
    full = Reconstruction(walk.motion, np.full(n, 0.01), np.zeros(n, bool),
                          scores={"novelty": np.full(n, 5.0)})
    for threshold, moved in ((2.5, True), (10.0, False)):
        method = SimpleNamespace(placements_=["right_ankle"], fps_=fps, gaps_missing=False,
                                 novelty_threshold=threshold)
        out, _ = fallback_recording(full, rec, method)
        assert (_arms_moved(out, walk, neutral) < 1e-6) is moved
    model = load_model(shipped_model("learned", "right_ankle"))
    assert model.novelty_threshold == model.novelty_threshold_ > 1.0


def test_a_shin_and_a_watch_observe_the_legs_and_the_arm(walk, neutral):
    """A shin lying still and a watch that moves (``right_ankle`` + ``left_wrist``): the legs
    stand (the shin sees them still), the arms stay the model's (the watch sees them move),
    the trunk, which neither sees, takes the standing pose and is the one part flagged; the
    report says both sensors' parts are observed."""
    n = walk.motion.num_frames
    signals = np.concatenate([still_signals(n), walk.signals], axis=1)
    full = Reconstruction(walk.motion, np.full(n, 0.01), np.zeros(n, bool))
    out, report = apply_fallback(full, signals, ["right_ankle", "left_wrist"], neutral)
    m, stand = out.motion, neutral.on(walk.motion.skeleton)[0]
    for g in ("legs", "trunk"):
        j = group_joints(m, g)
        assert geodesic(m.rotations[:, j], stand[j]).max() < 1e-6
    arms = group_joints(m, "arms")
    assert geodesic(m.rotations[:, arms], walk.motion.rotations[:, arms]).max() < 1e-6
    assert out.unreliable.all()  # the trunk is a guess
    j = report.to_json()
    assert j["observes"] == ["legs", "arms"]
    assert j["frames_fraction"] == {"legs": 1.0, "arms": 0.0, "trunk": 1.0}
    # the same watch alone (no leg sensor): the body's stillness is the watch's
    alone, _ = apply_fallback(full, signals[:, 6:], "left_wrist", neutral)
    assert geodesic(alone.motion.rotations[:, arms], walk.motion.rotations[:, arms]).max() \
        < 1e-6


def test_the_live_fallback_is_the_causal_offline_one_frame_for_frame(walk, neutral):
    """:class:`FallbackStream` fed a walk whose sensor lies still for 2 s, then walks, with a
    novelty rising through the threshold: the poses, roots, errors and flags of
    :func:`apply_fallback` with ``causal=True``, frame for frame; the causal still weight
    lags the centred one (the walk is seen half a window later)."""
    n = walk.motion.num_frames
    signals = walk.signals.copy()
    signals[:60] = still_signals(60)
    novelty = np.linspace(0.0, 12.0, n)
    full = Reconstruction(walk.motion, np.full(n, 0.01), np.zeros(n, bool),
                          scores={"novelty": novelty})
    off, report = apply_fallback(full, signals, "right_ankle", neutral, novelty_threshold=4.0,
                                 causal=True)
    live = FallbackStream(walk.motion.skeleton, walk.motion.fps, ["right_ankle"], neutral,
                          novelty_threshold=4.0)
    got = [live.step(signals[k], walk.motion.rotations[k], walk.motion.root[k], novelty[k],
                     0.01, False) for k in range(n)]
    rot = np.stack([g[0] for g in got])
    assert geodesic(rot, off.motion.rotations).max() < 1e-6
    np.testing.assert_allclose(np.stack([g[1] for g in got]), off.motion.root, atol=1e-9)
    np.testing.assert_allclose([g[2] for g in got], off.error_m, atol=1e-12)
    assert [g[3] for g in got] == off.unreliable.tolist()
    _, centred = apply_fallback(full, signals, "right_ankle", neutral, novelty_threshold=4.0)
    assert report.still[:60].min() > 0.99 and report.still[75:].max() < 0.01
    assert np.argmax(report.still < 0.5) > np.argmax(centred.still < 0.5)


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

    from imuloco.data import MODELS_DIR

    files = sorted(MODELS_DIR.glob("learned_*.npz"))
    assert any("+" in f.stem for f in files)  # the models reading several sensors too
    for path in files:
        with np.load(path, allow_pickle=False) as z:
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
