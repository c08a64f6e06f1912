"""The PCA local-model baseline (Tautges et al. 2008 sec. 5.2 after Chai and Hodgins 2005)."""

from __future__ import annotations

import numpy as np
import pytest

from imuloco.methods import load_model, pose
from imuloco.methods.pca_local import PCALocal
from imuloco.methods.training import synthesize
from imuloco.ops.rotations import to_matrix
from imuloco.sensors.simulate import attached_trajectories


@pytest.fixture(scope="module")
def fitted(sample_db):
    return PCALocal(max_nfev=3).fit(sample_db.where(content="walk"), ["left_ankle", "left_wrist"])


def test_kinematics_is_pose_decode_then_the_attached_sensors(fitted, sample_db):
    """The solver's one-frame, chain-only kinematics give pose.decode's root and the sensor
    positions and orientations of the full decoded pose, frame by frame."""
    rng = np.random.default_rng(0)
    motion = sample_db.clips[-1].slice(0, 12)
    vec = pose.encode(motion) + rng.normal(0, 0.05, (12, 1))  # off the database, not unit 6-D
    ref = pose.decode(vec, motion.skeleton, motion.fps, start=np.zeros(3))
    fitted._index()
    pos_ref, ori_ref = attached_trajectories(ref, fitted._anat)
    root, theta = ref.root[0], 0.0  # decode's first frame stands at start, heading 0
    for f in range(1, 12):
        ps, ori, new_root, th = fitted._kinematics(vec[f:f + 1], root, theta)
        root, theta = new_root[0], float(th[0])
        np.testing.assert_allclose(root, ref.root[f], atol=1e-9)
        np.testing.assert_allclose(ps[0], pos_ref[f], atol=1e-9)
        np.testing.assert_allclose(ori[0], to_matrix(ori_ref[f]), atol=1e-9)


def test_local_pca_reproduces_a_database_pose(fitted):
    q = fitted.poses_[100].astype(np.float64)
    mu, comp, _ = fitted._local_model(q)
    assert comp.shape[0] <= fitted.k and np.allclose(comp @ comp.T, np.eye(len(comp)))
    proj = mu + ((q - mu) @ comp.T) @ comp
    # the kept components explain most of the query's offset from the neighbours' mean
    assert np.linalg.norm(proj - q) < 0.5 * np.linalg.norm(q - mu)


@pytest.mark.parametrize("placements", [["right_wrist"], ["left_ankle", "right_ankle",
                                        "left_wrist", "right_wrist", "chest"]])
def test_reconstructs_any_sensor_set(sample_db, placements):
    m = PCALocal(max_nfev=2).fit(sample_db.where(content="run"), placements)
    ex = synthesize(sample_db.subset([1]), placements, "phone", seed=3)[0]
    out = m.reconstruct_signals(ex.signals[:15])
    assert out.num_frames == 15 and np.isfinite(out.rotations).all()
    assert np.isfinite(out.root).all()


def test_save_load_round_trip(fitted, sample_db, tmp_path):
    loaded = load_model(fitted.save(tmp_path / "p.npz"))
    assert isinstance(loaded, PCALocal) and loaded.get_params() == fitted.get_params()
    ex = synthesize(sample_db.subset([12]), fitted.placements_, "phone", seed=3)[0]
    a = fitted.reconstruct_signals(ex.signals[:10])
    b = loaded.reconstruct_signals(ex.signals[:10])
    assert np.allclose(a.rotations, b.rotations, atol=1e-6)


def test_local_model_is_the_neighbours_principal_axes(fitted):
    q = fitted.poses_[100].astype(np.float64)
    mu, comp, sd = fitted._local_model(q)
    # the k nearest database poses, by brute force
    dist = np.linalg.norm(fitted.poses_ / fitted.scale_ - q / fitted.scale_, axis=1)
    x = fitted.poses_[np.argsort(dist)[:fitted.k]].astype(np.float64) - mu
    _, s, vt = np.linalg.svd(x, full_matrices=False)
    d = len(comp)
    # the same subspace and spreads as the SVD's (axes up to sign)
    np.testing.assert_allclose(comp.T @ comp, vt[:d].T @ vt[:d], atol=1e-8)
    np.testing.assert_allclose(sd, s[:d] / np.sqrt(len(x) - 1) + 1e-6, rtol=1e-8)


def test_nearest_rows_are_the_exact_neighbours():
    from imuloco.methods.pca_local import _Rows

    rng = np.random.default_rng(1)
    x = rng.normal(0, 1, (500, 40)) * rng.uniform(0.1, 10, 40) + 100.0  # far from the origin
    rows = _Rows(x)
    for q in x[:20] + rng.normal(0, 0.3, (20, 40)):
        exact = np.argsort(np.linalg.norm(x - q, axis=1))
        assert set(rows.nearest(q, 25)) == set(exact[:25])
        assert rows.nearest(q, 1)[0] == exact[0]
    assert sorted(rows.nearest(x[0], 900)) == list(range(500))


def test_nearest_rows_along_a_path_are_exact():
    """Queries that follow a path, with jumps, get the exact neighbours whether the kept rows
    of an earlier query answer them or a full search does."""
    from imuloco.methods.pca_local import _Rows

    rng = np.random.default_rng(2)
    x = np.cumsum(rng.normal(0, 0.2, (3000, 12)), axis=0) + 50.0  # a curve, like poses
    rows = _Rows(x, reach=100)
    path = np.cumsum(rng.normal(0, 0.05, (300, 12)), axis=0) + x[1500]
    path[150:] += 3.0  # a jump: the kept rows no longer suffice
    kept = 0
    for q in path:
        before = rows._kept
        got = rows.nearest(q, 20)
        kept += rows._kept is before
        assert list(got) == sorted(np.argsort(np.linalg.norm(x - q, axis=1))[:20])
    assert 0 < kept < len(path)  # both ways were exercised
