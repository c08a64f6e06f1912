"""Eom et al. 2014: GPLVM gradients, HMM phase scoring, smoothing, fit/reconstruct/save."""

from __future__ import annotations

import numpy as np
import pytest
from hmmlearn.hmm import CategoricalHMM
from scipy.optimize import check_grad

from imuloco.measures import metrics
from imuloco.methods import get_method, load_model
from imuloco.methods.eom2014 import gplvm
from imuloco.methods.eom2014 import hmm as H
from imuloco.methods.postprocess import laplacian_smooth, laplacian_smooth_quaternions
from imuloco.methods.training import TEST_SEED_OFFSET, synthesize
from imuloco.ops.rotations import about_y, geodesic


def _toy_problem(seed: int = 0):
    rng = np.random.default_rng(seed)
    n, q = 14, 3
    t = np.linspace(0, 4 * np.pi, n)
    y = np.c_[np.sin(t), np.cos(t), np.sin(2 * t), t / 10] + 0.05 * rng.standard_normal((n, 4))
    cur = np.r_[1:7, 8:n]          # two sequences: frames 0-6 and 7-13
    prev = cur - 1
    ydot = rng.standard_normal((len(cur), 5))
    return y - y.mean(0), ydot - ydot.mean(0), cur, prev, q, rng


@pytest.mark.parametrize("x_prior", [0.0, 1.0])
def test_gplvm_gradient_matches_finite_differences(x_prior):
    y, ydot, cur, prev, q, rng = _toy_problem()
    theta = gplvm.init_params(y, ydot, cur, prev, q)
    theta = theta + 0.1 * rng.standard_normal(theta.size)

    def f(th):
        return gplvm.neg_log_posterior(th, y, ydot, cur, prev, q, x_prior)[0]

    def g(th):
        return gplvm.neg_log_posterior(th, y, ydot, cur, prev, q, x_prior)[1]

    scale = np.abs(g(theta)).max()
    assert check_grad(f, g, theta, epsilon=1e-6) < 1e-5 * max(scale, 1.0)


def test_gplvm_fit_increases_posterior_and_reproduces_training_poses():
    y, ydot, cur, prev, q, _ = _toy_problem()
    theta0 = gplvm.init_params(y, ydot, cur, prev, q)
    start = -gplvm.neg_log_posterior(theta0, y, ydot, cur, prev, q)[0]
    model = gplvm.fit_gplvm(y, ydot, cur, prev, q, maxiter=100)
    assert model.objective > start
    # the GP mean at the training latents reproduces the poses up to the noise level
    assert np.abs(model.pose(model.x) - y).max() < 0.2 * np.abs(y).max()
    # back-projection of a training pose lands where the GP mean gives that pose again
    xp = model.project(y)
    assert np.abs(model.pose(xp) - y).max() < 0.2 * np.abs(y).max()


def test_window_loglik_equals_hmmlearn_score():
    rng = np.random.default_rng(1)
    codes = rng.integers(0, 3, size=(40, 2))
    blocks = [[codes[:20]], [codes[20:]]]
    hmms = H.fit_phase_hmms(blocks, levels=3, n_states=2, seed=0)
    ll = H.window_loglik(codes, hmms, 10)
    assert ll.shape == (31, 2)
    for p in range(2):
        total = 0.0
        for d in range(2):
            ref = CategoricalHMM(n_components=2, n_features=3)
            ref.startprob_, ref.transmat_ = hmms.startprob[p, d], hmms.transmat[p, d]
            ref.emissionprob_ = hmms.emission[p, d]
            total += ref.score(codes[5:15, d:d + 1])
        assert ll[5, p] == pytest.approx(total, rel=1e-9)


def test_majority_vote_follows_the_windows():
    # 20 frames, windows of 5: the first 8 windows say phase 0, the rest phase 1
    votes = np.r_[np.zeros(8, int), np.ones(8, int)]
    frames = H.majority_vote(votes, 20, 5, 2)
    assert frames.shape == (20,)
    assert (frames[:8] == 0).all() and (frames[-8:] == 1).all()
    assert (np.diff(frames) >= 0).all()   # one switch only


def test_discretize_codes_slope_sign():
    t = np.linspace(0, 2 * np.pi, 200)
    sig = np.c_[np.sin(t)]
    edges = H.fit_levels([sig], 3)
    codes = H.discretize(sig, edges)[:, 0]
    assert codes[5] == 2 and codes[100] == 0          # rising near 0, falling near pi


def test_laplacian_smoothing_keeps_uniform_rotation_and_reduces_noise():
    t = np.linspace(0, 1.5, 60)
    clean = about_y(t)[:, None]
    assert np.abs(geodesic(laplacian_smooth_quaternions(clean, 0.5, 5), clean)).max() < 1e-9
    noisy = about_y(t + 0.05 * np.random.default_rng(0).standard_normal(60))[:, None]
    smooth = laplacian_smooth_quaternions(noisy, 0.5, 5)
    assert geodesic(smooth, clean).mean() < 0.7 * geodesic(noisy, clean).mean()
    line = np.c_[t, 2 * t]
    assert np.allclose(laplacian_smooth(line, 0.5, 4), line)


@pytest.fixture(scope="module")
def walk_split(sample_db):
    walks = sample_db.where(content="walk")
    train, test = walks.subset([0, 1, 2]), walks.subset([3])
    return train, synthesize(test, ["right_ankle"], "phone", TEST_SEED_OFFSET)


SMALL = {"per_type": False, "n_active": 80, "maxiter": 40, "hidden": (16,),
         "min_phase_frames": 20}


@pytest.fixture(scope="module")
def fitted(walk_split):
    train, _ = walk_split
    return get_method("eom2014", **SMALL).fit(train, ["right_ankle"], "phone", seed=0)


def test_fit_reconstruct_beats_the_mean_pose(walk_split, fitted):
    train, test = walk_split
    mean = get_method("mean").fit(train, ["right_ankle"], "phone", seed=0)
    ex = test[0]
    rec = fitted.reconstruct_signals(ex.signals)
    assert rec.num_frames == ex.motion.num_frames
    assert np.isfinite(rec.rotations).all() and np.isfinite(rec.root).all()
    err = metrics.mpjpe(ex.motion, metrics.align_heading(rec, ex.motion))
    base = metrics.mpjpe(ex.motion, metrics.align_heading(
        mean.reconstruct_signals(ex.signals), ex.motion))
    assert err < base
    assert len(fitted.models_) == 1 and len(fitted.models_[0].gp.x) >= 80


def test_save_load_round_trip(tmp_path, walk_split, fitted):
    _, test = walk_split
    path = fitted.save(tmp_path / "eom.npz")
    loaded = load_model(path)
    assert loaded.get_params() == fitted.get_params()
    a = fitted.reconstruct_signals(test[0].signals)
    b = loaded.reconstruct_signals(test[0].signals)
    np.testing.assert_allclose(a.rotations, b.rotations, atol=1e-12)
    np.testing.assert_allclose(a.root, b.root, atol=1e-12)


def test_stream_is_causal_and_finite(walk_split, fitted):
    _, test = walk_split
    sig = test[0].signals[:40]
    s1, s2 = fitted.stream(), fitted.stream()
    out1 = [s1.step(x) for x in sig]
    changed = sig.copy()
    changed[30:] += 5.0                      # the future must not change the past
    out2 = [s2.step(x) for x in changed]
    for (r1, p1), (r2, p2) in zip(out1[:30], out2[:30]):
        np.testing.assert_array_equal(r1, r2)
        np.testing.assert_array_equal(p1, p2)
    rot, root = out1[-1]
    assert rot.shape == (fitted.skeleton_.num_joints, 4) and root.shape == (3,)
    assert np.isfinite(rot).all() and np.isfinite(root).all()


@pytest.mark.parametrize("variant", ["mlp-no-hmm", "linear-latent"])
def test_ablation_variants_fit_and_reconstruct(walk_split, variant):
    train, test = walk_split
    m = get_method("eom2014", variant=variant, **SMALL).fit(train, ["right_ankle"], "phone")
    rec = m.reconstruct_signals(test[0].signals)
    assert np.isfinite(rec.positions()).all()


def test_unknown_variant_is_rejected(walk_split):
    train, _ = walk_split
    with pytest.raises(ValueError, match="variant"):
        get_method("eom2014", variant="nope", **SMALL).fit(train, ["right_ankle"], "phone")
