"""Baselines (mean, ridge, knn) and the shared window features."""

from __future__ import annotations

import numpy as np
import pytest

from imuloco.lab.protocols import split
from imuloco.measures import metrics
from imuloco.methods import get_method, method_class, method_names, pose
from imuloco.methods.features import (
    PoseIntegrator,
    WindowBuffer,
    fit_standardizer,
    standardize,
    windows,
)
from imuloco.methods.training import TEST_SEED_OFFSET, synthesize
from imuloco.ops.rotations import geodesic


def test_windows_causal_and_centred():
    x = np.arange(10, dtype=float).reshape(5, 2)  # rows (0,1), (2,3), ...
    w = windows(x, 3)
    assert w.shape == (5, 6)
    assert np.array_equal(w[0], [0, 1, 0, 1, 0, 1])  # edge padded with the first sample
    assert np.array_equal(w[3], [2, 3, 4, 5, 6, 7])  # samples 1, 2, 3, oldest first
    c = windows(x, 3, causal=False)
    assert np.array_equal(c[3], [4, 5, 6, 7, 8, 9])  # samples 2, 3, 4
    assert np.array_equal(c[4], [6, 7, 8, 9, 8, 9])
    assert np.array_equal(windows(x, 1), x)


def test_window_buffer_matches_offline_windows():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(20, 6))
    buf = WindowBuffer(7)
    online = np.stack([buf.push(s) for s in x])
    assert np.array_equal(online, windows(x, 7))


def test_standardizer():
    rng = np.random.default_rng(1)
    x = rng.normal(3.0, 2.0, size=(500, 3))
    x[:, 2] = 5.0  # constant column keeps scale 1
    mean, scale = fit_standardizer(x)
    z = standardize(x, mean, scale)
    assert np.allclose(z[:, :2].mean(0), 0) and np.allclose(z[:, :2].std(0), 1)
    assert scale[2] == 1.0 and np.all(z[:, 2] == 0)


def test_pose_integrator_equals_decode(sample_db):
    motion = sample_db.clips[0]
    vec = pose.encode(motion)
    integ = PoseIntegrator(motion.skeleton, motion.fps)
    frames = [integ.step(v) for v in vec]
    dec = pose.decode(vec, motion.skeleton, motion.fps)
    assert np.allclose(np.stack([f[1] for f in frames]), dec.root, atol=1e-9)
    assert geodesic(np.stack([f[0] for f in frames]), dec.rotations).max() < 1e-6


def test_registry_has_baselines():
    assert {"mean", "ridge", "knn"} <= set(method_names())
    for name in ("mean", "ridge", "knn"):
        assert method_class(name).name == name and method_class(name).summary


@pytest.fixture(scope="module")
def split_sample(sample_db):
    train, test = split(sample_db, "heldout-styles")
    examples = synthesize(test.subset([0, 4]), ["right_ankle"], "phone", TEST_SEED_OFFSET)
    return train, examples


@pytest.fixture(scope="module")
def fitted(split_sample):
    train, _ = split_sample
    return {name: get_method(name).fit(train, ["right_ankle"], "phone", seed=0)
            for name in ("mean", "ridge", "knn")}


@pytest.mark.parametrize("name", ["mean", "ridge", "knn"])
def test_online_equals_offline(fitted, split_sample, name):
    """Causal windows: streaming one sample at a time gives the offline reconstruction."""
    method = fitted[name]
    signals = split_sample[1][0].signals
    offline = method.reconstruct_signals(signals)
    stream = method.stream()
    frames = [stream.step(s) for s in signals]
    rot = np.stack([f[0] for f in frames])
    root = np.stack([f[1] for f in frames])
    assert np.allclose(root, offline.root, atol=1e-6)
    assert geodesic(rot, offline.rotations).max() < 1e-5


def test_learned_baselines_beat_the_mean_pose(fitted, split_sample):
    """Held-out styles: ridge and knn must use the sensor (lower MPJPE than the mean pose)."""
    errs = {}
    for name, method in fitted.items():
        e = []
        for ex in split_sample[1]:
            rec = metrics.align_heading(method.reconstruct_signals(ex.signals), ex.motion)
            e.append(metrics.mpjpe(ex.motion, rec))
        errs[name] = np.mean(e)
    assert errs["ridge"] < 0.9 * errs["mean"]
    assert errs["knn"] < 0.9 * errs["mean"]


def test_ridge_recovers_a_linear_map(sample_db):
    """If pose vectors were a linear function of the window, ridge (tiny alpha) would find it:
    check on the training data that it fits far better than the mean."""
    train = sample_db.subset([0, 1, 2])
    m = get_method("ridge", window=15, alpha=1e-3).fit(train, ["right_ankle"], "clean", 0)
    ex = synthesize(train, ["right_ankle"], "clean", 0)
    pred = m._predict(windows(ex[0].signals, 15))
    true = pose.encode(ex[0].motion)
    resid = np.mean((pred - true) ** 2)
    assert resid < 0.5 * np.mean((true - true.mean(0)) ** 2)


def test_knn_with_k1_returns_training_poses(sample_db):
    train = sample_db.subset([0, 1])
    m = get_method("knn", k=1).fit(train, ["right_ankle"], "clean", 0)
    ex = synthesize(train, ["right_ankle"], "clean", 0)
    pred = m._predict(windows(ex[0].signals, m.window))
    assert np.allclose(pred, pose.encode(ex[0].motion), atol=1e-5)
