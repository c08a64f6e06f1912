"""Sensor-to-segment calibration and device orientation."""

from __future__ import annotations

import numpy as np
import pytest

from imuloco.core.recording import Recording
from imuloco.ops.rotations import from_rotvec, geodesic, qinv, qmul, qrot, to_matrix
from imuloco.sensors.calibration import calibrate, estimate_mounting
from imuloco.sensors.reallog import read_log
from imuloco.sensors.simulate import simulate

TOLERANCE_DEG = 12.0  # walk-only: prior on the mean inclination + the leg's external rotation


def _turned(rec: Recording, rot: np.ndarray) -> Recording:
    """The same recording from a phone turned by ``rot`` (phone -> segment) on the segment."""
    return Recording(rec.times, qrot(qinv(rot), rec.acc), qrot(qinv(rot), rec.gyro),
                     list(rec.placements))


@pytest.fixture(scope="module")
def walks(sample_db):
    return [simulate(m, ["right_ankle"], 100.0, "clean") for m in sample_db.where(content="walk")
            .clips]


def _random_mountings(recs: list[Recording], seed: int, up_source: str, swings: int
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Each recording turned three times at random: the errors (degrees) of the mountings
    found against the truth, in total and of the y axis alone. Checks on the way that each
    estimate turns with the phone (exactly the unturned one composed with the turn)."""
    rng = np.random.default_rng(seed)
    errors, tilts = [], []
    for rec in recs:
        base = estimate_mounting(rec)
        assert base.up_source == up_source and base.swings >= swings
        for _ in range(3):
            rot = from_rotvec(rng.normal(size=3) * 1.5)
            est = estimate_mounting(_turned(rec, rot))
            assert np.degrees(geodesic(est.rotation, qmul(base.rotation, rot))) < 1e-6
            errors.append(np.degrees(geodesic(est.rotation, rot)))
            y_est, y_true = to_matrix(est.rotation)[1], to_matrix(rot)[1]
            tilts.append(np.degrees(np.arccos(np.clip(y_est @ y_true, -1, 1))))
    return np.array(errors), np.array(tilts)


def test_recovers_random_mountings(walks):
    errors, _ = _random_mountings(walks, 0, "walk", 3)
    assert np.median(errors) < 10.0 and max(errors) < TOLERANCE_DEG, np.round(errors, 1)


def test_calibrated_signals_match_unturned(walks):
    rec = walks[0]
    rot = from_rotvec(np.array([2.0, -0.5, 1.0]))
    cal, (mount,) = calibrate(_turned(rec, rot))
    ref, _ = calibrate(rec)
    np.testing.assert_allclose(cal.acc, ref.acc, atol=1e-8)
    np.testing.assert_allclose(cal.gyro, ref.gyro, atol=1e-8)
    # and close to the anatomical frame's own signals
    err = np.degrees(geodesic(mount.rotation, rot))
    for a, b in ((cal.gyro, rec.gyro), (cal.acc, rec.acc)):
        cos = np.sum(a * b, -1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
        assert np.degrees(np.arccos(np.clip(np.median(cos), -1, 1))) <= err + 1e-6
    assert np.corrcoef(cal.gyro[:, 0, 0], rec.gyro[:, 0, 0])[0, 1] > 0.98


def test_standing_still_gives_up_exactly(walks):
    """A phone that first rests 2 s on a vertical shank: gravity gives y to noise level."""
    rec = walks[1]
    rng = np.random.default_rng(3)
    n = 200
    t = np.concatenate([np.arange(n) * 0.01, rec.times - rec.times[0] + n * 0.01])
    acc = np.concatenate([[0.0, 9.81, 0.0] + rng.normal(0, 0.03, (n, 1, 3)), rec.acc])
    gyro = np.concatenate([rng.normal(0, 0.005, (n, 1, 3)), rec.gyro])
    rot = from_rotvec(np.array([0.3, 2.5, -0.7]))
    est = estimate_mounting(_turned(Recording(t, acc, gyro, ["right_ankle"]), rot))
    assert est.up_source == "still" and est.still_s >= 1.5
    y_est = to_matrix(est.rotation)[1]
    y_true = to_matrix(rot)[1]
    assert np.degrees(np.arccos(np.clip(y_est @ y_true, -1, 1))) < 1.0


@pytest.fixture(scope="module")
def back_walks(sample_db):
    """The sample's 12 walking clips (straight and turning) with a clean virtual L5 sensor."""
    return [simulate(m, ["lower_back"], 100.0, "clean") for c in
            ("walk", "walk-turn-left", "walk-turn-right") for m in sample_db.where(content=c).clips]


def test_recovers_random_lower_back_mountings(back_walks):
    """A lower-back sensor in any orientation: up from gravity (within 5 degrees: the virtual
    pelvis's lean spreads 1.6 degrees between clips, its roll 0.7), forward from the trunk's
    sway. The total error is mostly yaw: the pelvis against the sway's fore-aft line, which a
    turning walk yaws further (one turning clip: 29 degrees); a walk read backwards would be
    about 180 degrees off."""
    errors, tilts = _random_mountings(back_walks, 2, "mean", 2)
    assert np.median(errors) < 10.0 and max(errors) < 35.0, np.round(errors, 1)
    assert max(tilts) < 5.0, np.round(tilts, 1)


def test_lower_back_calibration_is_the_body_axes_leaned_back(back_walks):
    """Calibrated, the mean specific force leans forward of y by the virtual pelvis's lean,
    and the medio-lateral axis is x (body_axes' right is -x)."""
    from imuloco.sensors.calibration import BACK_WALK_INCLINATION, body_axes

    rec = _turned(back_walks[0], from_rotvec(np.array([0.4, -2.2, 1.1])))
    cal, (mount,) = calibrate(rec)
    g = cal.acc[:, 0].mean(0)
    assert np.degrees(np.arctan2(g[2], g[1])) == pytest.approx(BACK_WALK_INCLINATION, abs=0.5)
    assert abs(g[0]) < 1e-3 * np.linalg.norm(g)  # the mean of the 100 Hz grid it resamples to
    axes = body_axes(rec.acc[:, 0], 100.0)
    assert to_matrix(mount.rotation)[0] @ axes[1] == pytest.approx(-1.0, abs=1e-5)


def test_a_lower_back_that_never_walks_is_flagged(caplog):
    rng = np.random.default_rng(4)
    t = np.arange(1000) * 0.01
    acc = np.array([0.0, 9.81, 0.0]) + rng.normal(0, 0.02, (1000, 1, 3))
    rec = Recording(t, acc, rng.normal(0, 0.002, (1000, 1, 3)), ["lower_back"])
    mount = estimate_mounting(rec)
    assert mount.swings == 0 and "unreliable" in caplog.text
    with pytest.raises(ValueError, match="lower_back: .* shorter than 3 s"):
        estimate_mounting(Recording(t[:200], acc[:200], acc[:200] * 0, ["lower_back"]))


def test_non_leg_placement_refused(sample_db):
    rec = simulate(sample_db.clips[0], ["pelvis"], 100.0)
    with pytest.raises(ValueError, match="leg placement .* or 'lower_back'"):
        estimate_mounting(rec)
    cal, (mount,) = calibrate(rec)  # left as it is
    np.testing.assert_array_equal(cal.acc, rec.acc)
    assert mount.up_source == "none"


def test_fusion_tilt_follows_the_truth(sample_db):
    pytest.importorskip("ahrs")
    from imuloco.sensors.fusion import with_orientation

    rec = simulate(sample_db.where(content="walk").clips[0], ["pelvis"], 100.0, "phone", 1)
    fused = with_orientation(rec)
    up = np.array([0.0, 1.0, 0.0])
    truth = qrot(qinv(rec.orientation[:, 0]), up)
    est = qrot(qinv(fused.orientation[:, 0]), up)
    err = np.degrees(np.arccos(np.clip(np.sum(truth * est, -1), -1, 1)))
    assert np.median(err[rec.times > 2.0]) < 5.0


@pytest.mark.shared
def test_realworld_shin_mounting(shared_dir):
    rec, _ = read_log(shared_dir.parent / "realworld-shin" / "acc_walking_shin.csv")
    still = estimate_mounting(rec)
    walk = estimate_mounting(rec, min_still_s=np.inf)
    assert still.up_source == "still" and walk.up_source == "walk"
    m = to_matrix(still.rotation)
    assert np.degrees(np.arccos(m[1, 1])) < 20.0  # the phone's y runs up the shin
    # walk-only against standing: 12.9 deg, mostly about x (this walker's mean shank inclination
    # is ~8 deg, the sample's 21 deg prior is not theirs)
    assert np.degrees(geodesic(still.rotation, walk.rotation)) < 15.0
    assert still.swings > 300  # ~10 minutes of walking


@pytest.mark.parametrize("name", ["right_ankle", "left_ankle", "right_thigh", "left_thigh",
                                  "pelvis", "chest", "head"])
def test_anatomical_axes_during_walks(sample_db, name):
    """x points to the body's left and z forward while walking, on both legs: the Bandai rest
    pose alone would turn the right leg's frame half a turn and the chest's a quarter."""
    from imuloco.sensors.simulate import sensor_trajectory

    for motion in sample_db.where(content="walk").clips[:2]:
        sk = motion.skeleton
        _, pos = motion.fk()
        left = pos[:, sk.part("left_hip")] - pos[:, sk.part("right_hip")]
        left[:, 1] = 0.0
        left /= np.linalg.norm(left, axis=-1, keepdims=True)
        forward = np.cross(left, [0.0, 1.0, 0.0])
        _, q = sensor_trajectory(motion, name)
        x = qrot(q, np.array([1.0, 0.0, 0.0]))
        z = qrot(q, np.array([0.0, 0.0, 1.0]))
        assert np.mean(np.sum(x * left, -1)) > 0.8
        assert np.mean(np.sum(z * forward, -1)) > 0.7


@pytest.fixture(scope="module")
def foot_walks(sample_db):
    pytest.importorskip("gaitmap")
    return [simulate(m, [foot], 100.0, "clean") for m in sample_db.where(content="walk").clips
            for foot in ("right_foot", "left_foot")]


def test_recovers_random_foot_mountings(foot_walks):
    """A shoe sensor in any orientation: up from the resting foot, forward from its strides.
    What is left is mostly the mocap foot's toe-out (its bones against the walking direction),
    which the calibration does not know."""
    rng = np.random.default_rng(1)
    errors = []
    for rec in foot_walks:
        base = estimate_mounting(rec)
        assert base.up_source == "stances" and base.swings >= 3
        rot = from_rotvec(rng.normal(size=3) * 1.5)
        est = estimate_mounting(_turned(rec, rot))
        # turns with the sensor (to 2 degrees: gaitmap's ZUPT filter is not exactly invariant)
        assert np.degrees(geodesic(est.rotation, qmul(base.rotation, rot))) < 2.0
        errors.append(np.degrees(geodesic(est.rotation, rot)))
    # a flipped slope or forward axis would be 80-180 degrees off
    assert np.median(errors) < 10.0 and max(errors) < 30.0, np.round(errors, 1)


def test_a_foot_that_never_walks_is_refused():
    pytest.importorskip("gaitmap")
    t = np.arange(500) * 0.01
    acc = np.tile([0.0, 0.0, 9.81], (500, 1, 1))
    rec = Recording(t, acc, np.zeros_like(acc), ["left_foot"])
    with pytest.raises(ValueError, match="left_foot: a foot sensor is calibrated from walking"):
        calibrate(rec)


@pytest.mark.shared
def test_real_foot_sensors_turn_about_their_calibrated_medio_lateral_axis(shared_dir):
    """Real shoe IMUs (ipol-gait, pyshoe-vicon) come in their makers' axes; calibrated, the
    foot's swing turns it about x, as on the virtual foot sensors the models learn from."""
    pytest.importorskip("gaitmap")
    from imuloco.io.realimu import read_trials

    for name in ("ipol-gait", "pyshoe-vicon"):
        for trial in read_trials(shared_dir.parent / "real-imu" / name, limit=2):
            rec = trial.recording.select(["right_foot"])
            cal, (mount,) = calibrate(rec)
            share = np.mean(cal.gyro[:, 0] ** 2, axis=0)
            assert share[0] > 0.6 * share.sum(), (name, trial.name, share)
            assert mount.swings >= 4


def test_calibrating_a_shoe_sensor_and_measuring_its_gait_track_it_once(foot_walks):
    """``reconstruct`` calibrates a shoe sensor, then measures its gait from the same signals:
    the ZUPT track is computed once."""
    from imuloco.measures.sensorgait import sensor_gait
    from imuloco.sensors.foottrack import _track

    rec = Recording(foot_walks[0].times, foot_walks[0].acc + 1e-9, foot_walks[0].gyro,
                    list(foot_walks[0].placements))  # signals no other test has tracked
    before = _track.cache_info()
    calibrate(rec)
    gait = sensor_gait(rec, rec.placements[0])
    after = _track.cache_info()
    assert gait.measured and after.misses == before.misses + 1 and after.hits >= before.hits + 1


def test_gaitmaps_cacheable_kernels_are_cached_on_disk(foot_walks):
    """gaitmap compiles its kernels afresh in every process unless numba's on-disk cache is
    on: after a track, every kernel of GAITMAP_KERNELS exists in the installed gaitmap and
    caches (a renamed one fails here rather than silently compiling again)."""
    from importlib import import_module

    from numba.core.caching import NullCache

    from imuloco.sensors.foottrack import GAITMAP_KERNELS, foot_track

    w = foot_walks[0]
    foot_track(w.times, w.acc[:, 0] + 2e-9, w.gyro[:, 0])  # signals no other test tracked
    for module, name in GAITMAP_KERNELS:
        kernel = getattr(import_module(module), name)
        assert not isinstance(kernel._cache, NullCache), name
