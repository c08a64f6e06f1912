"""From a phone log to an animation: gait outputs, the pipeline, the CLI and the demo."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from imuloco.app.pipeline import DEMO_CLIP
from imuloco.cli import cli
from imuloco.core.recording import Recording
from imuloco.io.bvh import read_bvh
from imuloco.io.sensorlog import write_generic_csv
from imuloco.measures.gait import (
    gait_parameters,
    knee_flexion,
    plausibility,
    shank_swings,
    signal_cadence,
    signal_swing,
)
from imuloco.ops.rotations import from_rotvec, qrot
from imuloco.paths.truth import path_of_motion
from imuloco.phases import gait_phases
from imuloco.sensors.simulate import simulate


@pytest.fixture(scope="module")
def walks(sample_db):
    return sample_db.where(content=["walk", "walk-turn-left", "walk-turn-right"])


@pytest.fixture(scope="module")
def fitted(ridge_without_demo_clip):
    """ridge fitted on the sample without the demo clip (what the fallback does)."""
    return ridge_without_demo_clip


@pytest.fixture(scope="module")
def demo_clip(sample_db):
    return next(c for c in sample_db.clips if c.name == DEMO_CLIP)


@pytest.fixture(scope="module")
def log_file(tmp_path_factory, demo_clip):
    """A simulated phone log (generic CSV) of the demo clip."""
    rec = simulate(demo_clip, ["right_ankle"], rate=100.0, noise="phone", seed=3)
    return write_generic_csv(rec, tmp_path_factory.mktemp("log") / "walk.csv")


# ---- gait outputs -------------------------------------------------------------------------
def test_gait_parameters_are_consistent_on_captured_walks(walks):
    for clip in walks.clips:
        ph = gait_phases(clip)
        g = gait_parameters(clip, ph)
        assert g["cadence_spm"] == pytest.approx(ph.cadence_spm)
        assert g["steps"] == len(ph.steps["left"]) + len(ph.steps["right"])
        # two steps make a stride; speed is stride length times stride frequency
        assert g["stride_length_m"] == pytest.approx(2 * g["step_length_m"], rel=0.3)
        assert g["speed_mps"] == pytest.approx(
            g["stride_length_m"] * g["cadence_spm"] / 120.0, rel=0.3)
        assert 0.7 < g["speed_mps"] < 2.0 and 90 < g["cadence_spm"] < 140
        # walking: stance longer than swing (about 60/40), some double support
        assert 50 < g["stance_pct"] < 70 and g["stance_swing_ratio"] > 1.0
        assert 0 < g["double_support_pct"] < 35


def test_running_has_flight_not_double_support(sample_db):
    for clip in sample_db.where(content="run").clips:
        g = gait_parameters(clip)
        assert g["double_support_pct"] == 0.0 and g["stance_pct"] < 45


def test_gait_parameters_need_strikes(sample_db):
    still = sample_db.clips[0].slice(0, 3)
    g = gait_parameters(still)
    assert math.isnan(g["speed_mps"]) and math.isnan(g["step_length_m"])


def test_signal_cadence_matches_the_motion(walks):
    """The raw signal's stride frequency gives the captured cadence (clips >= 4 s)."""
    for clip in walks.clips:
        if clip.duration < 5:
            continue
        rec = simulate(clip, ["right_ankle"], noise="phone", seed=2)
        assert signal_cadence(rec) == pytest.approx(gait_phases(clip).cadence_spm, rel=0.08)


def test_signal_cadence_ignores_the_phone_orientation(walks):
    clip = walks.clips[-1]
    rec = simulate(clip, ["right_ankle"], noise="clean", seed=0)
    q = from_rotvec(np.array([0.4, -2.0, 1.1]))
    turned = Recording(rec.times, qrot(q, rec.acc), qrot(q, rec.gyro), rec.placements)
    assert signal_cadence(turned) == pytest.approx(signal_cadence(rec), abs=1.0)


def test_signal_swing_is_the_shanks(walks):
    """A shin sensor's raw gyroscope gives how far its shank turns in a stride, as the
    motion's own shank pitch does, in any phone orientation (the principal axis)."""
    q = from_rotvec(np.array([0.4, -2.0, 1.1]))
    for clip in walks.clips:
        if clip.duration < 5:
            continue
        rec = simulate(clip, ["right_ankle"], rate=50.0, noise="phone", seed=2)
        swing = signal_swing(rec)
        assert 40 < swing < 100  # a walking shank's 60-80 degrees
        assert swing == pytest.approx(shank_swings(clip)["right"], rel=0.05)
        turned = Recording(rec.times, qrot(q, rec.acc), qrot(q, rec.gyro), rec.placements)
        assert signal_swing(turned) == pytest.approx(swing, rel=1e-6)


def test_signal_swing_of_a_pure_swing_despite_a_gyroscope_bias():
    """A sensor turning 2 x 30 degrees about one axis at 0.9 strides/s (with the second
    harmonic a leg's rate has) reads 60 degrees; a constant bias of 0.05 rad/s, which would
    add 3 degrees a second to the angle, is left out."""
    t = np.arange(0.0, 30.0, 0.01)
    w = 2 * np.pi * 0.9
    rate = np.radians(30.0) * w * np.cos(w * t) + 0.3 * np.sin(2 * w * t) + 0.05
    axis = np.array([0.3, -0.8, 0.52]) / np.linalg.norm([0.3, -0.8, 0.52])
    gyro = rate[:, None, None] * axis
    rec = Recording(t, np.zeros_like(gyro) + [0.0, 9.81, 0.0], gyro, ["right_ankle"])
    angle = np.degrees(np.ptp(np.radians(30.0) * np.sin(w * t)
                              - 0.3 / (2 * w) * np.cos(2 * w * t)))
    assert signal_swing(rec) == pytest.approx(angle, rel=0.03)
    assert math.isnan(signal_swing(Recording(t[:300], rec.acc[:300], rec.gyro[:300],
                                             ["right_ankle"])))  # 3 s: no cadence


def test_plausibility_of_captured_motion(walks):
    for clip in walks.clips:
        p = plausibility(clip)
        assert p["finite"] == 1.0
        assert p["knee_out_of_range_pct"] == 0 and p["hip_out_of_range_pct"] == 0
        assert 40 < p["knee_max_deg"] < 90  # swing-phase knee flexion of walking ~60-70
        assert p["foot_skate_cm_s"] < 12  # captured feet hardly slide
        if clip.duration >= 5:  # both shanks swing alike in a walk
            assert p["left_shank_swing_deg"] == pytest.approx(p["right_shank_swing_deg"],
                                                              rel=0.15)
        k = knee_flexion(clip, "left")
        assert k.shape == (clip.num_frames,) and np.all(k >= 0)


# ---- the pipeline -----------------------------------------------------------------------------
def test_choose_method_falls_back_to_a_baseline_fitted_on_the_sample(monkeypatch):
    from imuloco.app import pipeline

    monkeypatch.setattr(pipeline, "shipped_model", lambda method, placement: None)
    method, note = pipeline.choose_method(exclude=[DEMO_CLIP])
    assert method.name == pipeline.FALLBACK
    assert "fitted" in note and "15 clips" in note
    assert method.placements_ == ["right_ankle"]
    with pytest.raises(KeyError, match="unknown method"):
        pipeline.choose_method("no-such-method")


def test_the_shipped_learned_model_is_the_default():
    from imuloco.app import pipeline

    path = pipeline.shipped_model("learned", "right_ankle")
    if path is None:
        pytest.skip("no learned model is shipped in imuloco/data/models")
    pytest.importorskip("torch")
    method, note = pipeline.choose_method()
    assert method.name == "learned" and "pretrained" in note


def test_reconstruct_file_gives_a_walk_on_the_training_skeleton(log_file, fitted, demo_clip):
    from imuloco.app.pipeline import reconstruct_file
    from imuloco.measures.metrics import mpjpe

    motion, report = reconstruct_file(log_file, fitted=fitted)
    assert motion.skeleton.names == fitted.skeleton_.names
    assert motion.fps == 30.0
    assert abs(motion.num_frames - demo_clip.num_frames) <= 2
    assert report["recording"]["format"] == "generic"
    assert report["calibration"][0]["rotation_deg"] < 20  # simulated: a few degrees off
    p = report["plausibility"]
    assert p["finite"] == 1.0 and p["knee_out_of_range_pct"] == 0
    gt_cadence = gait_phases(demo_clip).cadence_spm
    assert report["signal_cadence_spm"] == pytest.approx(gt_cadence, rel=0.08)
    assert report["signal_swing_deg"] == pytest.approx(shank_swings(demo_clip)["right"], rel=0.05)
    # the reconstruction walks at the captured rhythm (strike counts of jittery baselines
    # are inflated by spurious contacts: only checked to exist)
    assert report["gait"]["cadence_rhythm_spm"] == pytest.approx(gt_cadence, rel=0.1)
    assert report["gait"]["cadence_spm"] > 0
    n = min(motion.num_frames, demo_clip.num_frames)
    assert mpjpe(demo_clip.slice(0, n), motion.slice(0, n)) < 12.0
    json.dumps(report.to_json())  # JSON-ready
    # the shank's path drove the root: the animation's strides are the path's (issue 40)
    path = report["path"]
    assert path["source"] == "shank-pivot" and path["strides"] >= 3
    assert abs(path["stride_agreement_pct"]) < 2
    truth = path_of_motion(demo_clip).distance_m()
    assert path["animation"]["distance_m"] == pytest.approx(truth, rel=0.1)


def test_calibration_makes_the_phone_orientation_irrelevant(fitted, demo_clip):
    """A phone strapped turned gives the same reconstruction once calibrated."""
    from imuloco.app.pipeline import reconstruct_recording
    from imuloco.measures.metrics import mpjpe

    rec = simulate(demo_clip, ["right_ankle"], rate=100.0, noise="phone", seed=4)
    q = from_rotvec(np.array([0.0, 0.0, np.pi / 2]) + 0.2)  # screen turned a quarter and more
    turned = Recording(rec.times, qrot(q, rec.acc), qrot(q, rec.gyro), rec.placements)
    a, _ = reconstruct_recording(rec, fitted)
    b, info = reconstruct_recording(turned, fitted)
    assert info["calibration"][0]["rotation_deg"] > 80
    assert mpjpe(a, b) < 1.0
    c, _ = reconstruct_recording(turned, fitted, calibrate=False)
    assert mpjpe(a, c) > 2 * mpjpe(a, b)  # without calibration the turn matters


# ---- the CLI -------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def model_file(tmp_path_factory, fitted):
    return fitted.save(tmp_path_factory.mktemp("model") / "ridge.npz")


def test_cli_reconstruct_writes_bvh_and_never_overwrites(tmp_path, log_file, model_file):
    out = tmp_path / "out.bvh"
    args = ["reconstruct", str(log_file), "--model", str(model_file), "-o", str(out),
            "--html", str(tmp_path / "v.html"), "--report", str(tmp_path / "r.json")]
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 0, res.output
    assert "cadence" in res.output and "model file" in res.output
    motion = read_bvh(out)
    assert motion.num_frames > 200 and (tmp_path / "v.html").stat().st_size > 10_000
    assert json.loads((tmp_path / "r.json").read_text())["method"] == "ridge"
    # a second run must not replace the user's files without --force
    out.write_text("mine")
    res = CliRunner().invoke(cli, args)
    assert res.exit_code != 0 and "--force" in res.output
    assert out.read_text() == "mine"
    res = CliRunner().invoke(cli, [*args, "--force"])
    assert res.exit_code == 0, res.output
    assert read_bvh(out).num_frames == motion.num_frames


def test_cli_reconstruct_reports_bad_files(tmp_path, model_file):
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,acc_x,acc_y,acc_z,gyro_x,gyro_y,gyro_z\n0,1,2,3,4,5,6\n0.01,1,2,x,4,5,6\n")
    res = CliRunner().invoke(cli, ["reconstruct", str(bad), "--model", str(model_file), "-o",
                                   str(tmp_path / "o.bvh")])
    assert res.exit_code != 0 and "bad.csv:3" in res.output
    assert not (tmp_path / "o.bvh").exists()


def test_bvh_parses_in_an_independent_reader(tmp_path, fitted, log_file):
    """The written BVH, read by bvhio (a second, unrelated BVH implementation), gives the
    same world joint positions as our forward kinematics."""
    bvhio = pytest.importorskip("bvhio")
    from imuloco.app.pipeline import reconstruct_file
    from imuloco.io.bvh import write_bvh

    motion, _ = reconstruct_file(log_file, fitted=fitted)
    motion = motion.slice(0, 40)
    path = write_bvh(motion, tmp_path / "r.bvh")
    root = bvhio.readAsHierarchy(str(path))
    pos = motion.positions()
    for f in (0, 17, 39):
        root.loadPose(f)
        got = {j.Name: np.array(j.PositionWorld) / 100.0 for j, *_ in root.layout()}  # cm
        for k, name in enumerate(motion.skeleton.names):
            np.testing.assert_allclose(got[name], pos[f, k], atol=1e-5)


def test_cli_render(tmp_path, demo_clip):
    from imuloco.io.bvh import write_bvh

    bvh = write_bvh(demo_clip.slice(0, 20), tmp_path / "m.bvh")
    res = CliRunner().invoke(cli, ["render", str(bvh), "--ground-truth", str(bvh), "-o",
                                   str(tmp_path / "m.html"), "-o", str(tmp_path / "m.png")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "m.png").stat().st_size > 1000
    res = CliRunner().invoke(cli, ["render", str(bvh), "-o", str(tmp_path / "m.avi")])
    assert res.exit_code != 0 and "unsupported" in res.output


@pytest.mark.slow
def test_demo_writes_everything(tmp_path, read_mp4):
    """``imuloco demo`` end to end (the README's first command)."""
    import imageio.v3 as iio

    out = tmp_path / "demo"
    res = CliRunner().invoke(cli, ["demo", "--out", str(out)])
    assert res.exit_code == 0, res.output
    report = json.loads((out / "report.json").read_text())
    for name in report["files"]:
        assert (out / name).stat().st_size > 0, name
    m = report["metrics"]
    assert all(v is not None and np.isfinite(v) for v in m.values())
    assert m["mpjpe_cm"] < 12
    gt, rec = report["gait_ground_truth"], report["gait"]
    assert rec["cadence_rhythm_spm"] == pytest.approx(gt["cadence_spm"], rel=0.1)
    assert report["signal_cadence_spm"] == pytest.approx(gt["cadence_spm"], rel=0.08)
    motion = read_bvh(out / "reconstruction.bvh")
    video = read_mp4(out / "demo.mp4", 640, 384)
    assert video.shape[0] == motion.num_frames and video.shape[2] == 2 * 320
    assert iio.imread(out / "demo.gif").shape[0] == (motion.num_frames + 1) // 2
    assert "| mpjpe_cm |" in (out / "report.md").read_text()
    # the shipped model's predicted error, beside the actual one
    c, check = report["confidence"], report["confidence_check"]
    assert c["available"] and check["mean_predicted_error_m"] == pytest.approx(
        c["mean_error_m"], abs=2e-4)
    assert check["mean_actual_error_m"] > 0 and check["ratio"] > 0
    assert "## Confidence" in (out / "report.md").read_text()
    assert "predicted error" in res.output
    res = CliRunner().invoke(cli, ["demo", "--out", str(out)])
    assert res.exit_code != 0 and "--force" in res.output


# ---- the real recording --------------------------------------------------------------------
@pytest.mark.shared
def test_real_shin_recording_gives_a_plausible_walk(shared_dir):
    """60 s of the RealWorld shin recording (a real phone, irregular timestamps)."""
    from imuloco.app.pipeline import choose_method, reconstruct_recording
    from imuloco.sensors.reallog import read_log

    acc = shared_dir.parent / "realworld-shin" / "acc_walking_shin.csv"
    if not acc.exists():
        pytest.skip("../shared/data/realworld-shin is absent")
    rec, report = read_log(acc)
    assert report.source_rate == pytest.approx(50.0, rel=0.05)
    keep = (rec.times >= 20.0) & (rec.times < 80.0)  # walking, no gap
    rec = Recording(rec.times[keep] - 20.0, rec.acc[keep], rec.gyro[keep], rec.placements)
    method, _ = choose_method()
    motion, _ = reconstruct_recording(rec, method)
    raw = signal_cadence(rec)
    assert 95 < raw < 120  # ~0.9 strides per second
    p = plausibility(motion)
    assert p["finite"] == 1.0
    assert p["knee_out_of_range_pct"] == 0 and p["hip_out_of_range_pct"] == 0
    assert p["knee_max_deg"] > 30  # the legs bend
    assert p["foot_skate_cm_s"] < 30
    g = gait_parameters(motion)
    assert g["cadence_rhythm_spm"] == pytest.approx(raw, rel=0.1)
    assert 0.3 < g["speed_mps"] < 2.0


def test_cli_reconstruct_units(tmp_path, log_file, model_file):
    """``--units m`` writes the same motion in metres (what Blender reads at scale 1)."""
    from imuloco.io.bvh import read_bvh

    outs = {}
    for units in ("cm", "m"):
        outs[units] = tmp_path / f"{units}.bvh"
        res = CliRunner().invoke(cli, ["reconstruct", str(log_file), "--model", str(model_file),
                                       "-o", str(outs[units]), "--units", units])
        assert res.exit_code == 0, res.output
    cm, m = read_bvh(outs["cm"], unit="cm"), read_bvh(outs["m"], unit="m")
    np.testing.assert_allclose(m.positions(), cm.positions(), atol=1e-6)
    # the numbers themselves are 100 times smaller
    np.testing.assert_allclose(read_bvh(outs["m"], unit="cm").positions(),
                               cm.positions() / 100, atol=1e-8)
    res = CliRunner().invoke(cli, ["reconstruct", str(log_file), "--model", str(model_file),
                                   "-o", str(tmp_path / "x.bvh"), "--units", "mm"])
    assert res.exit_code == 2
