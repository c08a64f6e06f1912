"""Physics of the virtual sensors."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from imuloco.core.motion import Motion
from imuloco.ops.rotations import about_y, from_rotvec, qinv, qmul, qrot
from imuloco.sensors.noise import NOISE_PRESETS
from imuloco.sensors.placement import PRESETS
from imuloco.sensors.simulate import sensor_trajectory, simulate

OMEGA = 1.3  # rad/s


@pytest.fixture(scope="module")
def skeleton(sample_db):
    return sample_db.skeleton


def _posed(skeleton, frames: int, yaw_rate: float = 0.0, velocity=(0.0, 0.0, 0.0)) -> Motion:
    """The skeleton's standing pose from the sample, turned at ``yaw_rate`` about the vertical
    and translated at ``velocity``."""
    t = np.arange(frames) / 30.0
    rot = np.zeros((frames, skeleton.num_joints, 4))
    rot[..., 3] = 1.0
    rot[:, 0] = qmul(about_y(yaw_rate * t), rot[:, 0])
    root = np.array([0.0, 1.0, 0.0]) + np.outer(t, velocity)
    return Motion(skeleton, rot, root, 30.0, "posed")


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_resting_sensor_reads_plus_g_upward(skeleton, name):
    motion = _posed(skeleton, 60)
    rec = simulate(motion, [name], rate=100.0)
    _, q = sensor_trajectory(motion, name)
    expected = qrot(qinv(q[0]), np.array([0.0, 9.81, 0.0]))
    np.testing.assert_allclose(rec.acc[:, 0], np.broadcast_to(expected, (rec.num_samples, 3)),
                               atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(rec.acc[:, 0], axis=-1), 9.81, atol=1e-6)
    np.testing.assert_allclose(rec.gyro, 0.0, atol=1e-9)


def test_constant_velocity_reads_only_gravity(skeleton):
    rec = simulate(_posed(skeleton, 60, velocity=(1.2, 0.0, -0.7)), ["right_ankle"])
    np.testing.assert_allclose(np.linalg.norm(rec.acc[:, 0], axis=-1), 9.81, atol=1e-6)


@pytest.mark.parametrize("name", ["right_ankle", "pelvis", "right_wrist", "head"])
def test_spinning_segment_reads_omega(skeleton, name):
    rec = simulate(_posed(skeleton, 120, yaw_rate=OMEGA), [name], rate=100.0)
    inner = slice(20, -20)  # away from the spline's end conditions
    np.testing.assert_allclose(np.linalg.norm(rec.gyro[inner, 0], axis=-1), OMEGA, rtol=1e-4)
    # the rotation is about world up: in the sensor frame, the gyro vector is that axis
    _, q = sensor_trajectory(_posed(skeleton, 120, yaw_rate=OMEGA), name)
    axis0 = qrot(qinv(q[0]), np.array([0.0, OMEGA, 0.0]))
    np.testing.assert_allclose(rec.gyro[inner, 0], np.broadcast_to(axis0, rec.gyro[inner, 0].shape),
                               atol=1e-3)


def test_gyro_norm_independent_of_fixed_rotation(sample_db):
    motion = sample_db.where(content="walk").clips[0]
    base = PRESETS["right_ankle"]
    turned = replace(base, name="turned", rotation=tuple(from_rotvec(np.array([0.5, -1.0, 2.0]))))
    a = simulate(motion, [base])
    b = simulate(motion, [turned])
    np.testing.assert_allclose(np.linalg.norm(a.gyro, axis=-1), np.linalg.norm(b.gyro, axis=-1),
                               atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(a.acc, axis=-1), np.linalg.norm(b.acc, axis=-1),
                               atol=1e-9)


def test_jitter_holds_up_to_its_rate_and_scales_with_the_period_above():
    """The phone's 2 ms jitter is unchanged up to JITTER_RATE (every simulation behind the
    results) and the same fraction of the period above it (2 ms at 10 kHz is 20 periods)."""
    from imuloco.sensors.noise import JITTER_RATE, sample_times

    model = replace(NOISE_PRESETS["phone"], drop_rate=0.0)
    for rate in (50.0, JITTER_RATE, 1000.0, 10_000.0):
        times = sample_times(20.0, rate, model, np.random.default_rng(0))
        assert len(times) == round(20 * rate) + 1
        spread = np.std(times[1:-1] - np.arange(1, len(times) - 1) / rate)
        expected = model.jitter_s * min(1.0, JITTER_RATE / rate)
        assert spread == pytest.approx(expected, rel=0.05), rate


def test_noise_is_seeded_and_bounded(sample_db):
    motion = sample_db.clips[0]
    a = simulate(motion, ["right_ankle"], noise="phone", seed=3)
    b = simulate(motion, ["right_ankle"], noise="phone", seed=3)
    c = simulate(motion, ["right_ankle"], noise="phone", seed=4)
    np.testing.assert_array_equal(a.acc, b.acc)
    assert not np.array_equal(a.times, c.times)
    phone = NOISE_PRESETS["phone"]
    assert np.abs(a.acc).max() <= phone.acc_range and np.abs(a.gyro).max() <= phone.gyro_range
    gaps = np.diff(a.times)
    assert gaps.min() > 0 and gaps.max() > 0.015  # jittered, with dropped samples


def test_fk_matches_hand_computed_positions(two_joint_skeleton):
    """A root turned 90 degrees about +Z puts a child 1 m above it at 1 m along -X."""
    from imuloco.ops.kinematics import fk

    h = np.sqrt(0.5)
    rot = np.array([[0.0, 0.0, h, h], [0.0, 0.0, 0.0, 1.0]])
    grot, pos = fk(rot, np.array([1.0, 2.0, 3.0]), two_joint_skeleton.offsets,
                   two_joint_skeleton.parents)
    np.testing.assert_allclose(pos, [[1.0, 2.0, 3.0], [0.0, 2.0, 3.0]], atol=1e-12)
    np.testing.assert_allclose(np.abs(grot[1] @ rot[0]), 1.0, atol=1e-12)  # same rotation


def test_a_strap_passes_gravity_and_rolls_by_its_static_gain():
    """At rest the strapped phone reads what the rigid sensor reads; under a slow, steady
    angular acceleration about x it settles at roll_gain x alpha, and its gyroscope's y reads
    the roll's rate."""
    from imuloco.sensors.strap import Strap, strapped

    rate, n = 400.0, 4000
    t = np.arange(n) / rate
    acc = np.tile([0.3, 9.81, -0.2], (n, 1))
    still = strapped(acc, np.zeros((n, 3)), rate, Strap(4.0, 0.5, 0.003))
    np.testing.assert_allclose(still[0], acc, atol=1e-9)
    np.testing.assert_allclose(still[1], 0.0, atol=1e-12)
    alpha = 20.0  # rad/s^2, constant: gyro x a ramp
    gyro = np.stack([alpha * t, np.zeros(n), np.zeros(n)], 1)
    acc2, gyro2, roll = strapped(acc, gyro, rate, Strap(4.0, 0.5, 0.003))
    assert roll[-1] == pytest.approx(0.003 * alpha, rel=1e-3)
    # gravity turned with the phone about y: y unchanged, the norm kept
    assert acc2[-1, 1] == pytest.approx(9.81)
    assert np.linalg.norm(acc2[-1]) == pytest.approx(np.linalg.norm(acc[-1]))
    np.testing.assert_allclose(gyro2[-1], [np.cos(roll[-1]) * alpha * t[-1], 0.0,
                                           np.sin(roll[-1]) * alpha * t[-1]], rtol=1e-3,
                               atol=1e-6)
    rate_of_roll = np.gradient(roll, 1 / rate)
    np.testing.assert_allclose(gyro2[:, 1], rate_of_roll, atol=1e-9)


def test_a_strap_damps_what_is_faster_than_it():
    from imuloco.sensors.strap import Strap, strapped

    rate = 400.0
    t = np.arange(8000) / rate
    strap = Strap(5.0, 0.7, 0.0)
    for hz, low, high in ((0.5, 0.97, 1.03), (40.0, 0.0, 0.2)):
        acc = np.stack([np.sin(2 * np.pi * hz * t)] * 3, 1)
        out = strapped(acc, np.zeros_like(acc), rate, strap)[0]
        gain = out[4000:, 0].std() / acc[4000:, 0].std()
        assert low < gain < high, (hz, gain)


def test_a_strapped_recording_stays_consistent_with_its_orientation(sample_db):
    """The roll goes into the recorded orientation too: the gyroscope is still its rate."""
    from scipy.spatial.transform import Rotation

    from imuloco.sensors.strap import Strap

    clip = sample_db.where(content="walk").clips[0]
    rigid = simulate(clip, ["right_ankle"], 100.0, "clean")
    rec = simulate(clip, ["right_ankle"], 100.0, "clean", strap=Strap(3.0, 0.3, 0.003))
    r = Rotation.from_quat(rec.orientation[:, 0])
    rate = (r[:-1].inv() * r[1:]).as_rotvec() / np.diff(rec.times)[:, None]
    mid = 0.5 * (rec.gyro[1:, 0] + rec.gyro[:-1, 0])
    assert np.median(np.linalg.norm(rate - mid, axis=1)) < 0.05
    # and it rolls: more rotation about the shank's long axis than the rigid sensor's
    assert rec.gyro[:, 0, 1].std() > 1.2 * rigid.gyro[:, 0, 1].std()


def test_shank_placements_are_known():
    """The shank's swing is read from sensors on a shank only (a report's signal swing)."""
    from imuloco.sensors.placement import PRESETS

    shank = {name for name, p in PRESETS.items() if p.on_shank}
    assert {"right_ankle", "left_ankle"} <= shank
    assert not shank & {"right_foot", "left_foot", "lower_back"}
