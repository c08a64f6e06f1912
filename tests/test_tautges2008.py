"""Tautges et al. 2008 multilinear model: HOSVD, eq. 17's vertical rotation, synthesis,
reconstruction against the mean baseline, model files."""

from __future__ import annotations

import numpy as np
import pytest
from tensorly.tenalg import multi_mode_dot

from imuloco.methods import get_method, load_model
from imuloco.methods.tautges2008.align import eq17_distance, vertical_rotation
from imuloco.methods.tautges2008.method import Tautges2008
from imuloco.methods.tautges2008.tensor import (
    chain_cycles,
    gait_cycles,
    hosvd,
    register_cycle,
)
from imuloco.methods.training import synthesize
from imuloco.ops.rotations import about_y, geodesic, qrot
from imuloco.sensors.placement import anatomical_frame, get_placement
from imuloco.sensors.simulate import attached_trajectories, sensor_trajectory

PLACEMENTS = ["right_ankle", "left_wrist"]


def test_hosvd_without_truncation_is_exact():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(4, 5, 6, 3, 2))
    core, factors = hosvd(x, list(x.shape))
    assert np.allclose(multi_mode_dot(core, factors), x, atol=1e-10)
    for u in factors:  # orthonormal columns (eq. 1)
        assert np.allclose(u.T @ u, np.eye(u.shape[1]), atol=1e-10)
    # truncating the last two modes loses something, but less than dropping them outright
    core_t, f_t = hosvd(x, [4, 5, 6, 2, 1])
    err = np.linalg.norm(multi_mode_dot(core_t, f_t) - x)
    assert 1e-6 < err < np.linalg.norm(x)


def test_vertical_rotation_recovers_a_known_yaw():
    rng = np.random.default_rng(1)
    b = rng.normal(size=(50, 3))
    for theta in (0.3, -2.0, 3.0):
        a = qrot(about_y(theta), b) + rng.normal(scale=0.01, size=b.shape)
        assert np.isclose(vertical_rotation(a, b), theta, atol=0.01)
    # per sensor, in eq. 17: two sensors turned differently, distance back to the noise
    a = np.stack([qrot(about_y(0.5), b), qrot(about_y(-1.0), b)], axis=1)  # (F, S, 3)
    d, th = eq17_distance(a, np.stack([b, b], axis=1))
    assert np.allclose(th, [0.5, -1.0]) and d < 1e-20


def test_attached_trajectories_match_the_single_sensor_path(sample_db):
    motion = sample_db.clips[-1].slice(0, 40)
    poses = motion.rotations[::5]
    frames = [anatomical_frame(motion.skeleton, get_placement(p), poses) for p in PLACEMENTS]
    pos, ori = attached_trajectories(motion, frames)
    for s, p in enumerate(PLACEMENTS):
        ref_pos, ref_ori = sensor_trajectory(motion, p)
        assert np.allclose(pos[:, s], ref_pos, atol=1e-9)
        assert np.allclose(np.abs(np.sum(ori[:, s] * ref_ori, axis=-1)), 1.0)


@pytest.fixture(scope="module")
def fitted(sample_db):
    return Tautges2008().fit(sample_db, PLACEMENTS, "phone", seed=0)


def test_rows_of_the_natural_modes_give_back_the_tensor_cycles(fitted, sample_db):
    """Eq. 2: one row per natural mode synthesizes one of the original (registered) cycles."""
    model = fitted.models_["walk"]
    motion = sample_db.where(content="walk", style="active").clips[0]
    a, b = gait_cycles(motion)[0]
    rot, _ = register_cycle(motion, a, b, fitted.frames)
    errs = [np.degrees(geodesic(model.synthesize(us, ur)[0], rot)).max()
            for us in model.rot_natural[0] for ur in model.rot_natural[1]]
    assert min(errs) < 1e-6


def test_chained_cycles_are_continuous(fitted):
    model = fitted.models_["walk"]
    rot, root = model.synthesize(*model.x_mean)
    u = np.array([1.0 - 1e-6, 1.0, 2.0 - 1e-6, 2.0])
    q, p = chain_cycles(rot, root, u)
    assert np.degrees(geodesic(q[0], q[1])).max() < 0.5  # root: the mean cycle closes nearly
    assert np.degrees(geodesic(q[2], q[3])).max() < 0.5
    assert np.abs(p[0] - p[1]).max() < 1e-4 and np.abs(p[2] - p[3]).max() < 1e-4
    assert np.linalg.norm(p[3] - p[1]) > 0.5  # a walking cycle moves about a stride


def test_reconstruction_beats_the_mean_pose(fitted, sample_db):
    db = sample_db.where(content="walk", style="exhausted")
    ex = synthesize(db, PLACEMENTS, "phone", seed=1_000_003)[0]
    out = fitted.reconstruct_signals(ex.signals[:64])
    assert out.num_frames == 64 and np.isfinite(out.rotations).all()
    gt = ex.motion.slice(0, 64)
    mean = get_method("mean").fit(sample_db, PLACEMENTS).reconstruct_signals(ex.signals[:64])
    err = np.degrees(geodesic(out.rotations[:, 1:], gt.rotations[:, 1:])).mean()
    err_mean = np.degrees(geodesic(mean.rotations[:, 1:], gt.rotations[:, 1:])).mean()
    assert fitted.content_.startswith("walk")
    assert err < 0.8 * err_mean


def test_save_load_round_trip(fitted, sample_db, tmp_path):
    path = fitted.save(tmp_path / "t.npz")
    loaded = load_model(path)
    assert isinstance(loaded, Tautges2008) and loaded.get_params() == fitted.get_params()
    ex = synthesize(sample_db.subset([0]), PLACEMENTS, "phone", seed=3)[0]
    a = fitted.reconstruct_signals(ex.signals[:20])
    b = loaded.reconstruct_signals(ex.signals[:20])
    assert np.allclose(a.rotations, b.rotations) and np.allclose(a.root, b.root)


@pytest.mark.parametrize("placements", [["left_wrist"], ["left_ankle", "right_ankle",
                                        "left_wrist", "right_wrist", "chest"]])
def test_any_sensor_set_and_the_sensor_frame_variant(sample_db, placements):
    m = Tautges2008(frame="sensor", max_iter=3).fit(sample_db.where(content="run"), placements)
    ex = synthesize(sample_db.subset([0]), placements, "phone", seed=3)[0]
    out = m.reconstruct_signals(ex.signals[:20])
    assert out.num_frames == 20 and np.isfinite(out.rotations).all()


def test_bad_frame_is_refused():
    with pytest.raises(ValueError, match="frame"):
        Tautges2008(frame="global")
