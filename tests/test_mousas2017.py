"""Mousas 2017: transitions, forward algorithm, registration, fit/stream, model files."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.special import logsumexp

from imuloco.measures.metrics import mpjpe
from imuloco.methods import get_method, load_model
from imuloco.methods.mousas2017.forward import Topology, forward
from imuloco.methods.mousas2017.registration import split_by_speed, warp_matrix
from imuloco.methods.mousas2017.stream import matrix_exp, matrix_from_6d, matrix_to_quat
from imuloco.methods.training import TEST_SEED_OFFSET, synthesize
from imuloco.ops.rotations import from_6d

A_FRAME = (0.5, 0.3, 0.2)   # unequal, so that a mix-up of self/next/skip shows
A_PHASE = (0.2, 0.5, 0.3)


def tiny_topology() -> Topology:
    """Phases 0, 2, 5 of 8: two segments of 3 frames, one of 1 frame, two of 2 frames."""
    nxt = np.zeros((8, 8))
    nxt[0, 2] = 1.0
    nxt[2, 5], nxt[2, 0] = 3.0, 1.0
    nxt[5, 0] = 1.0
    return Topology(np.array([0, 2, 5]), np.array([2, 1, 2]), np.array([3, 1, 2]), nxt,
                    A_FRAME, A_PHASE)


def reference_matrix() -> np.ndarray:
    """The tiny topology's transition matrix, written out from the rules one state at a time
    (frame-major blocks: state = start + j H + s)."""
    blocks = [(0, 2, 3), (2, 1, 1), (5, 2, 2)]  # (phase, H, L)
    states, start = [], 0
    for b, (h, big_h, length) in enumerate(blocks):
        states += [(b, j, s, start + j * big_h + s) for j in range(length)
                   for s in range(big_h)]
        start += big_h * length
    index = {(b, j, s): i for b, j, s, i in states}
    n = len(states)
    nxt = {0: {2: 1.0}, 2: {5: 0.75, 0: 0.25}, 5: {0: 1.0}}
    phase_of = {b: h for b, (h, _, _) in enumerate(blocks)}
    block_of = {h: b for b, h in phase_of.items()}
    a = np.zeros((n, n))
    for b, j, s, i in states:
        length = blocks[b][2]
        out = 0.0
        for step, p in enumerate(A_FRAME):
            if j + step < length:
                a[i, index[(b, j + step, s)]] += p
            else:
                out += p
        h = phase_of[b]
        to_phase = {hh: 0.0 for hh in nxt}
        to_phase[h] += A_PHASE[0]
        for hh, p in nxt[h].items():
            to_phase[hh] += A_PHASE[1] * p
        for hh in to_phase:
            to_phase[hh] += A_PHASE[2] / 3
        for hh, p in to_phase.items():
            bb = block_of[hh]
            big_h = blocks[bb][1]
            for ss in range(big_h):
                a[i, index[(bb, 0, ss)]] += out * p / big_h
    return a


def test_transitions_follow_the_rules():
    topo = tiny_topology()
    a = topo.dense()
    np.testing.assert_allclose(a, reference_matrix(), atol=1e-12)
    np.testing.assert_allclose(a.sum(axis=1), 1.0, atol=1e-12)


def test_forward_matches_brute_force():
    topo = tiny_topology()
    a = reference_matrix()
    n = topo.num_states
    rng = np.random.default_rng(0)
    logb = rng.normal(0.0, 3.0, size=(4, n))
    alpha, loglik = forward(topo, logb)
    pi = np.full(n, 1.0 / n)
    # every path of 4 states
    joint = np.zeros(n)
    for path in itertools.product(range(n), repeat=4):
        p = pi[path[0]] * np.exp(logb[0, path[0]])
        for t in range(1, 4):
            p *= a[path[t - 1], path[t]] * np.exp(logb[t, path[t]])
        joint[path[-1]] += p
    assert loglik == pytest.approx(np.log(joint.sum()), rel=1e-10)
    np.testing.assert_allclose(alpha[-1], joint / joint.sum(), atol=1e-12)


@pytest.mark.parametrize("a_frame", [A_FRAME, (1 / 3, 1 / 3, 1 / 3), (0.0, 0.6, 0.4)])
def test_unscaled_prediction_is_the_prediction_over_a_self(a_frame):
    """The stream's fast path (``scaled=False``) differs from the transition only by the
    common factor a_self, for unequal, the paper's equal, and a zero a_self."""
    topo = tiny_topology()
    topo = Topology(topo.phases, topo.counts, topo.lengths, topo.next_phase, a_frame, A_PHASE)
    alpha = np.random.default_rng(3).dirichlet(np.ones(topo.num_states))
    ref = alpha @ np.stack([topo.predict(row) for row in np.eye(topo.num_states)])
    np.testing.assert_allclose(topo.predict(alpha), ref, atol=1e-15)
    scale = a_frame[0] if a_frame[0] > 0 else 1.0
    out, work = np.empty_like(alpha), np.empty_like(alpha)
    np.testing.assert_allclose(topo.predict(alpha, out, work, scaled=False) * scale, ref,
                               atol=1e-15)
    if a_frame == A_FRAME:
        np.testing.assert_allclose(ref, alpha @ reference_matrix(), atol=1e-15)


def test_forward_long_stream_does_not_underflow():
    """10,000 steps with emissions that would underflow any unscaled forward pass, against
    a log-space reference; missing samples (NaN rows) only propagate the transitions."""
    topo = tiny_topology()
    log_a = np.log(np.maximum(reference_matrix(), 1e-300))
    n, steps = topo.num_states, 10_000
    rng = np.random.default_rng(1)
    logb = -rng.uniform(0.0, 200.0, size=(steps, n))
    logb[5000:5030] = np.nan
    alpha, loglik = forward(topo, logb)
    assert np.all(np.isfinite(alpha)) and np.isfinite(loglik)
    np.testing.assert_allclose(alpha.sum(axis=1), 1.0, atol=1e-12)
    log_alpha = np.log(np.full(n, 1.0 / n)) + logb[0]
    for t in range(1, steps):
        x = log_alpha[:, None] + log_a          # logsumexp over the previous state, inline
        m = x.max(axis=0)
        log_alpha = m + np.log(np.exp(x - m).sum(axis=0))
        if not np.isnan(logb[t, 0]):
            log_alpha = log_alpha + logb[t]
    assert loglik == pytest.approx(logsumexp(log_alpha), rel=1e-9)
    np.testing.assert_allclose(alpha[-1], np.exp(log_alpha - logsumexp(log_alpha)), atol=1e-9)
    np.testing.assert_allclose(alpha[5001], alpha[5000] @ reference_matrix(), atol=1e-12)


def test_topology_rejects_unequal_lengths_and_bad_probabilities():
    with pytest.raises(ValueError, match="summing to 1"):
        Topology(np.array([0]), np.array([1]), np.array([2]), np.zeros((8, 8)),
                 (0.5, 0.5, 0.5))
    with pytest.raises(ValueError, match="increase"):
        Topology(np.array([2, 1]), np.array([1, 1]), np.array([2, 2]), np.zeros((8, 8)))


def test_warp_matrix_registers_a_time_stretched_copy():
    from dtaidistance import dtw_ndim

    t = np.linspace(0, 1, 6)
    ref = np.stack([np.sin(3 * t), np.cos(2 * t)], axis=1)
    slow = np.stack([np.sin(3 * np.linspace(0, 1, 12)), np.cos(2 * np.linspace(0, 1, 12))], 1)
    w = warp_matrix(dtw_ndim.warping_path(slow, ref), 12, 6)
    np.testing.assert_allclose(w.sum(axis=1), 1.0)
    assert np.abs(w @ slow - ref).max() < 0.15
    assert np.abs(slow[::2] - ref).max() > np.abs(w @ slow - ref).max()


def test_split_by_speed_caps_lengths():
    speed = np.abs(np.sin(np.linspace(0, 6 * np.pi, 90)))
    pieces = split_by_speed(speed, 15)
    assert pieces[0][0] == 0 and pieces[-1][1] == 90
    assert all(b - a <= 15 for a, b in pieces)
    assert all(p[1] == q[0] for p, q in itertools.pairwise(pieces))


def test_rotation_helpers_match_scipy():
    rot = Rotation.random(200, random_state=3)
    q = matrix_to_quat(rot.as_matrix())
    np.testing.assert_allclose(np.abs((q * rot.as_quat()).sum(-1)), 1.0, atol=1e-12)
    half_turns = Rotation.from_rotvec(np.pi * np.array([[1, -1, 0], [0, 0, 1]]) /
                                      np.array([[2**0.5], [1.0]]))
    q = matrix_to_quat(half_turns.as_matrix())
    np.testing.assert_allclose(np.abs((q * half_turns.as_quat()).sum(-1)), 1.0, atol=1e-12)
    rv = np.random.default_rng(0).normal(0, 0.7, (50, 3))
    rv[0] = 0.0
    np.testing.assert_allclose(matrix_exp(rv), Rotation.from_rotvec(rv).as_matrix(), atol=1e-12)
    d6 = np.random.default_rng(1).normal(size=(30, 6))
    np.testing.assert_allclose(matrix_from_6d(d6), Rotation.from_quat(from_6d(d6)).as_matrix(),
                               atol=1e-12)


# ---- fitted on the bundled sample ---------------------------------------------------------

@pytest.fixture(scope="module")
def fitted(sample_db):
    """Fitted on 15 sample clips; the 16th (a walk) held out."""
    names = [lab["name"] for lab in sample_db.labels]
    test_i = names.index("dataset-2_walk_normal_001")
    train = sample_db.subset([i for i in range(len(sample_db)) if i != test_i])
    model = get_method("mousas2017").fit(train, ["right_ankle"], "phone", seed=0)
    mean = get_method("mean").fit(train, ["right_ankle"], "phone", seed=0)
    test = synthesize(sample_db.subset([test_i]), ["right_ankle"], "phone",
                      TEST_SEED_OFFSET)[0]
    return model, mean, test


def test_fit_and_stream_beat_the_mean_pose(fitted):
    model, mean, test = fitted
    rec = model.reconstruct_signals(test.signals)
    assert rec.num_frames == test.motion.num_frames
    assert np.all(np.isfinite(rec.rotations)) and np.all(np.isfinite(rec.root))
    err, err_mean = mpjpe(test.motion, rec), mpjpe(test.motion, mean.reconstruct_signals(
        test.signals))
    assert err < 0.8 * err_mean, (err, err_mean)
    # the online stream with per-step foot pinning gives the same poses as the offline path
    st = model.stream()
    out = [st.step(s) for s in test.signals]
    rot = np.stack([o[0] for o in out])
    np.testing.assert_allclose(np.abs((rot * rec.rotations).sum(-1)), 1.0, atol=1e-9)
    root = np.stack([o[1] for o in out])
    np.testing.assert_allclose(root, rec.root, atol=1e-9)
    assert set(model.states_.group_phase.tolist()) <= set(range(8))


def test_stream_filter_matches_the_offline_forward(fitted):
    """The stream's float32 forward step (floors, exp clamp, unscaled transitions) gives the
    filtering distribution of the float64 offline :func:`forward` to float32 tolerance, with
    and without missing samples."""
    model, _, test = fitted
    sig = test.signals[:60].copy()
    sig[30:40] = np.nan
    logb = model.states_.log_emission_batch(sig)
    logb[30:40] = np.nan
    topo = model.lower_
    topo64 = Topology(topo.phases, topo.counts, topo.lengths, topo.next_phase, topo.a_frame,
                      topo.a_phase)
    alpha, _ = forward(topo64, logb)
    st = model.stream(beam=0)
    for t, sample in enumerate(sig):
        st.step(sample)
        np.testing.assert_allclose(st.alpha, alpha[t], atol=2e-5, err_msg=f"step {t}")


def test_full_beam_is_the_exact_forward_step(fitted):
    """A beam at least as wide as the number of segments prunes nothing: its forward
    variable and poses are the exact step's (float64 against float32), missing samples too."""
    model, _, test = fitted
    sig = test.signals[:60].copy()
    sig[30:40] = np.nan
    width = int(model.lower_.counts.sum())
    exact, beam = model.stream(beam=0), model.stream(beam=width)
    for t, sample in enumerate(sig):
        r0, p0 = exact.step(sample)
        r1, p1 = beam.step(sample)
        np.testing.assert_allclose(beam.state_posterior(), exact.state_posterior(),
                                   rtol=1e-4, atol=1e-7, err_msg=f"step {t}")
        np.testing.assert_allclose(np.abs((r0 * r1).sum(-1)), 1.0, atol=1e-6)
        np.testing.assert_allclose(p1, p0, atol=1e-6)
        assert beam.phase == exact.phase


@pytest.mark.parametrize("width", [3, 12])
def test_beam_step_is_the_exact_step_pruned(fitted, width):
    """Each beam step is the exact forward step (transitions of :meth:`Topology.predict`,
    emissions, floors) applied to the beam's previous forward variable, then cut to the
    ``width`` segments of largest mass and renormalised: no segment that belongs in the beam
    is missed, also among those entering from outside it."""
    from imuloco.methods.mousas2017 import stream as stream_mod
    from imuloco.methods.mousas2017.beam import SegmentBeam

    model, _, test = fitted
    topo = model.lower_
    # unequal transition probabilities, so that a mix-up of self/next/skip or phases shows
    topo64 = Topology(topo.phases, topo.counts, topo.lengths, topo.next_phase, A_FRAME,
                      A_PHASE)
    st = model.stream(beam=width)
    st._beam = tables = SegmentBeam(topo64, model.states_, width, stream_mod.EMISSION_FLOOR,
                                    stream_mod.ALPHA_FLOOR)
    sig = test.signals[:40].copy()
    sig[20:23] = np.nan
    st.step(sig[0])
    for t in range(1, len(sig)):
        prev = st.state_posterior()
        st.step(sig[t])
        pred = topo64.predict(prev)
        if not np.isnan(sig[t]).any():
            ll = model.states_.log_emission_batch(sig[t][None])[0]
            # the beam's emissions are relative to the best state it computes (the kept
            # segments and every first frame); the floor is relative to the same
            cand = np.unique(np.concatenate([tables.states[tables.seg].ravel(),
                                             tables.states[:, 0]]))
            cand = cand[cand < topo.num_states]
            pred = pred * (np.exp(ll - ll[cand].max()) + stream_mod.EMISSION_FLOOR)
        mass = np.append(pred, 0.0)[tables.states].sum(1)           # per segment
        keep = tables.seg
        out = np.setdiff1d(np.arange(mass.size), keep)
        assert keep.size == width and np.unique(keep).size == width
        # the kept segments are those of largest mass (ties, as at a missing sample, either way)
        assert mass[keep].min() >= mass[out].max() * (1 - 1e-9), f"step {t}"
        dense = np.zeros(topo.num_states + 1)
        dense[tables.states[keep]] = np.append(pred, 0.0)[tables.states[keep]]
        dense = dense[:-1] / dense.sum()
        dense[tables.states[keep][tables.valid[keep]]] += stream_mod.ALPHA_FLOOR
        np.testing.assert_allclose(st.state_posterior(), dense, rtol=1e-5, atol=1e-12,
                                   err_msg=f"step {t}")


def test_exp_clamp_changes_no_bit(fitted, monkeypatch):
    """Log emissions clamped at max - 60 before exp give the same forward variable, bit for
    bit, as the unclamped exp (they fall below the emission floor's half ulp), on samples far
    from every state, where the clamp acts on most states."""
    from imuloco.methods.mousas2017 import stream as stream_mod

    model, _, test = fitted
    sig = test.signals[:30].copy()
    sig[10:15, :3] += 40.0                   # m/s^2: far from every state
    logb = model.states_.log_emission_batch(sig[10:15])
    assert np.mean(logb - logb.max(axis=1, keepdims=True) < stream_mod.EXP_CLAMP) > 0.5
    runs = []
    for clamp in (stream_mod.EXP_CLAMP, -np.inf):
        monkeypatch.setattr(stream_mod, "EXP_CLAMP", clamp)
        st = model.stream(beam=0)
        alphas = []
        for x in sig:
            st.step(x)
            alphas.append(st.alpha.copy())
        runs.append(alphas)
    np.testing.assert_array_equal(np.stack(runs[0]), np.stack(runs[1]))


def test_stream_survives_a_dropout(fitted):
    model, _, test = fitted
    sig = test.signals.copy()
    sig[60:90] = np.nan                      # 1 s at 30 fps
    rec = model.reconstruct_signals(sig)
    assert np.all(np.isfinite(rec.rotations)) and np.all(np.isfinite(rec.root))
    full = model.reconstruct_signals(test.signals)
    late = slice(150, None)
    # well after the samples return, the joints move as in the undisturbed reconstruction
    # (the root's heading and position are integrated, so they keep the offset they took)
    np.testing.assert_allclose(np.abs((rec.rotations[late, 1:] * full.rotations[late, 1:]
                                       ).sum(-1)), 1.0, atol=1e-3)
    with pytest.raises(ValueError, match="shape"):
        model.stream().step(np.zeros(5))


def test_recording_gaps_reach_the_model_as_missing(fitted):
    from imuloco.core.recording import Recording
    from imuloco.methods.training import to_frames
    from imuloco.sensors.resample import find_gaps
    from imuloco.sensors.simulate import simulate

    model, _, test = fitted
    rec = simulate(test.motion.slice(0, 120), ["right_ankle"], 100.0, "phone", seed=5)
    keep = (rec.times < 1.0) | (rec.times > 2.0)
    cut = Recording(rec.times[keep], rec.acc[keep], rec.gyro[keep], rec.placements)
    out = model.reconstruct(cut)
    (gap,) = find_gaps(cut.times, 0.1)
    times = cut.times[0] + np.arange(out.num_frames) / model.fps_
    rows = to_frames(cut, times - cut.times[0], model.fps_)
    missing = (times > gap.start) & (times < gap.stop)
    assert 28 <= missing.sum() <= 31
    rows[missing] = np.nan
    ref = model.reconstruct_signals(rows)
    np.testing.assert_allclose(out.rotations, ref.rotations)
    assert np.all(np.isfinite(out.rotations))


@pytest.mark.parametrize("second", ["left_ankle", "left_wrist"])
def test_two_sensors_are_one_joint_observation(sample_db, second):
    """The paper reads one ankle; given two sensors, the frame states' Gaussians are over
    both sensors' 12 channels together (eq. 2 with y of both): the second sensor is read
    (its signal, shifted by half a second, changes the poses) and the reconstruction still
    beats the mean pose."""
    placements = ["right_ankle", second]
    names = [lab["name"] for lab in sample_db.labels]
    test_i = names.index("dataset-2_walk_normal_001")
    train = sample_db.subset([i for i in range(len(sample_db)) if i != test_i])
    model = get_method("mousas2017").fit(train, placements, "phone", seed=0)
    mean = get_method("mean").fit(train, placements, "phone", seed=0)
    test = synthesize(sample_db.subset([test_i]), placements, "phone", TEST_SEED_OFFSET)[0]
    assert model.states_.mu_y.shape[1] == 12  # both sensors, one Gaussian
    rec = model.reconstruct_signals(test.signals)
    err = mpjpe(test.motion, rec)
    assert err < 0.8 * mpjpe(test.motion, mean.reconstruct_signals(test.signals)), err
    moved = test.signals.copy()
    moved[:, 6:] = np.roll(moved[:, 6:], 15, axis=0)
    assert mpjpe(rec, model.reconstruct_signals(moved)) > 0.1 * err


def test_save_load_round_trip(fitted, tmp_path):
    model, _, test = fitted
    path = model.save(tmp_path / "m.npz")
    again = load_model(path)
    assert again.get_params() == model.get_params()
    a = model.reconstruct_signals(test.signals[:80])
    b = again.reconstruct_signals(test.signals[:80])
    np.testing.assert_array_equal(a.rotations, b.rotations)
    np.testing.assert_array_equal(a.root, b.root)


def test_bad_hyperparameters_are_refused(sample_db):
    with pytest.raises(ValueError, match="blend"):
        get_method("mousas2017", blend=0.0).fit(sample_db.subset([0]), ["right_ankle"])
    with pytest.raises(ValueError, match="engine"):
        get_method("mousas2017", engine="cuda").fit(sample_db.subset([0]), ["right_ankle"])


# ---- the compiled step (engine numba, the `fast` extra) ------------------------------------
def _as_float64(model):
    """A copy of a fitted model whose forward variable and emissions are float64 (the numpy
    and the compiled step then agree to float64 rounding, not float32's), with unequal
    transition probabilities (so that a mix-up of self/next/skip or phases shows)."""
    import copy

    from imuloco.methods.mousas2017.model import FrameStates

    m = copy.copy(model)
    fs = model.states_
    m.states_ = FrameStates(**{k: (v.astype(np.float64) if v.dtype == np.float32 else v)
                               for k, v in fs.arrays().items()})
    low = model.lower_
    m.lower_ = Topology(low.phases, low.counts, low.lengths, low.next_phase, A_FRAME, A_PHASE,
                        dtype=np.float64)
    return m


def _enlarged(model, reps: int, seed: int = 0):
    """A synthetic model ``reps`` times larger: every segment of every phase repeated with
    its frames' means moved by noise (a valid model: emissions recomputed from the means)."""
    import copy

    from imuloco.methods.mousas2017.model import FrameStates

    fs, rng = model.states_, np.random.default_rng(seed)
    src = []
    for g0, st, big_h, length in fs.blocks:
        for j in range(length):
            src.append(np.tile(st + j * big_h + np.arange(big_h), reps))
    src = np.concatenate(src)
    mu_x = fs.mu_x[src] + rng.normal(0, 0.02, (src.size, fs.mu_x.shape[1])).astype(np.float32)
    mu_y = fs.mu_y[src] + rng.normal(0, 0.3, (src.size, fs.mu_y.shape[1])).astype(np.float32)
    group = fs.group[src]
    lin = np.einsum("nde,ne->dn", fs.prec[group], mu_y.astype(np.float64))
    old = (fs.lin[:, src].astype(np.float64) * fs.mu_y[src].T).sum(0)
    const = fs.const[src] + 0.5 * old - 0.5 * (lin * mu_y.T).sum(0)
    m = copy.copy(model)
    m.states_ = FrameStates(mu_x=mu_x, mu_y=mu_y, group=group, reg=fs.reg,
                            cond_var=fs.cond_var, prec=fs.prec, lin=lin.astype(np.float32),
                            const=const.astype(np.float32), group_phase=fs.group_phase,
                            group_frame=fs.group_frame, group_count=fs.group_count * reps)
    m.block_count_ = model.block_count_ * reps
    m._build(model.skeleton_.num_joints)
    return m


def _run(stream, signals):
    """Per step: forward variable, upper level, phase, interpolated features, pose."""
    out = []
    for s in signals:
        rot, root = stream.step(s)
        out.append((stream.state_posterior(), stream.alpha_up.copy(), stream.phase,
                    stream.pose_vector.copy(), stream.y_bar.copy(), stream.variance.copy(),
                    stream.contacts.copy(), rot, root))
    return out


@pytest.mark.parametrize("reps", [1, 12])
def test_compiled_step_is_the_numpy_step(fitted, reps):
    """engine=numba computes the numpy step's forward variables, phase, interpolation and pose:
    in float64 to 1e-9 (rounding only: sums in another order), on the sample's model and on
    a synthetic model 12 times larger, with missing samples and the foot clean-up."""
    model, _, test = fitted
    model = _as_float64(_enlarged(model, reps) if reps > 1 else model)
    sig = test.signals[:90].copy()
    sig[40:48] = np.nan
    ref = _run(model.stream(engine="numpy"), sig)
    out = _run(model.stream(engine="numba"), sig)
    assert model.lower_.num_states > 5000 or reps == 1
    for t, (a, b) in enumerate(zip(ref, out)):
        _assert_same_step(a, b, t)


def _assert_same_step(a, b, t: int) -> None:
    """Two :func:`_run` records of step t: the same phase, the rest equal to 1e-9."""
    assert a[2] == b[2], f"phase at step {t}"
    for name, u, v in zip(("alpha", "alpha_up", "-", "x", "y_bar", "variance",
                           "contacts", "rotations", "root"), a, b):
        if name != "-":
            np.testing.assert_allclose(v, u, rtol=1e-9, atol=1e-12,
                                       err_msg=f"{name} at step {t}")


def test_compiled_step_float32_and_the_offline_path(fitted):
    """The shipped float32 model: both engines agree to float32 rounding, also through
    reconstruct_signals (which takes the model's engine)."""
    model, _, test = fitted
    sig = test.signals[:90].copy()
    sig[40:48] = np.nan
    for a, b in zip(_run(model.stream(engine="numpy"), sig),
                    _run(model.stream(engine="numba"), sig)):
        assert a[2] == b[2]
        np.testing.assert_allclose(b[0], a[0], rtol=1e-4, atol=1e-12)
        np.testing.assert_allclose(b[7], a[7], atol=1e-5)
        np.testing.assert_allclose(b[8], a[8], atol=1e-5)
    recs = []
    for engine in ("numpy", "numba"):
        model.set_params(engine=engine)
        recs.append(model.reconstruct_signals(sig))
    model.set_params(engine="auto")
    np.testing.assert_allclose(recs[1].rotations, recs[0].rotations, atol=1e-5)
    np.testing.assert_allclose(recs[1].root, recs[0].root, atol=1e-5)


@pytest.mark.parametrize("reps, width", [(1, 8), (12, 48), (12, 700)])
def test_compiled_beam_step_is_the_numpy_beam_step(fitted, reps, width):
    """With a beam, engine=numba (:func:`.compiled.beam_step`) computes the numpy beam step's
    kept segments, forward variables, phase, interpolation and pose: in float64 to 1e-9, on
    the sample's model and one 12 times larger, with missing samples; beams that prune (the
    wider one lets hundreds of segments enter a step)."""
    model, _, test = fitted
    model = _as_float64(_enlarged(model, reps) if reps > 1 else model)
    assert model.lower_.counts.sum() > width
    sig = test.signals[:90].copy()
    sig[40:48] = np.nan
    ref_st, out_st = model.stream(beam=width, engine="numpy"), model.stream(beam=width,
                                                                             engine="numba")
    for t, s in enumerate(sig):
        ref, out = _run(ref_st, [s])[0], _run(out_st, [s])[0]
        np.testing.assert_array_equal(out_st._beam.seg, ref_st._beam.seg, err_msg=f"step {t}")
        _assert_same_step(ref, out, t)


def test_engine_without_numba(fitted, monkeypatch):
    """Without numba: engine=numba is a MissingExtraError naming the extra, auto is numpy."""
    import sys

    from imuloco.errors import MissingExtraError

    model, _, test = fitted
    monkeypatch.setitem(sys.modules, "numba", None)  # import numba raises ImportError
    monkeypatch.delitem(sys.modules, "imuloco.methods.mousas2017.compiled", raising=False)
    with pytest.raises(MissingExtraError, match=r"imuloco\[fast\]"):
        model.stream(engine="numba")
    st = model.stream()
    assert st.engine == "numpy"
    ref = model.stream(engine="numpy")
    for s in test.signals[:5]:
        np.testing.assert_array_equal(st.step(s)[0], ref.step(s)[0])


def test_top_segments_ties_go_to_the_lower_index():
    from imuloco.methods.mousas2017 import compiled
    from imuloco.methods.mousas2017.stream import TIE_RTOL, top_segments

    w = np.array([0.1, 0.5, 0.3, 0.3 * (1 + TIE_RTOL / 10), 0.9, 0.3, 0.2, 0.3])
    for k, want in ((1, [4]), (2, [1, 4]), (3, [1, 2, 4]), (4, [1, 2, 3, 4]),
                    (5, [1, 2, 3, 4, 5])):
        assert sorted(top_segments(w, k).tolist()) == want
        assert sorted(compiled._largest(w, k, TIE_RTOL).tolist()) == want


def test_a_cold_numba_cache_is_announced(tmp_path, caplog):
    """The first compile takes about 25 s of CPU: without cached kernels, a warning says so;
    with them, nothing."""
    from imuloco.methods.mousas2017.stream import _say_if_compiling

    class Module:  # what is read of imuloco.methods.mousas2017.compiled
        def __init__(self) -> None:
            self.__file__ = str(tmp_path / "compiled.py")
            self.emission = type("Kernel", (), {})()
            self.emission._cache = type("Cache", (), {"cache_path": str(tmp_path)})()

    with caplog.at_level("WARNING"):
        _say_if_compiling(Module())
    assert "compiling its online step with numba" in caplog.text
    caplog.clear()
    (tmp_path / "compiled.emission-44.py311.nbi").write_bytes(b"")
    with caplog.at_level("WARNING"):
        _say_if_compiling(Module())
    assert caplog.text == ""


def test_keep_largest_ties_go_to_the_lower_index():
    """The beam's selection of its width segments, numpy and compiled: the k largest, ties
    (within TIE_RTOL of the k-th) to the lower index; the compiled radix select finds the k-th
    largest as a sort does."""
    from imuloco.methods.mousas2017 import compiled
    from imuloco.methods.mousas2017.beam import TIE_RTOL, keep_largest

    w = np.array([0.1, 0.5, 0.3, 0.3 * (1 + TIE_RTOL / 10), 0.9, 0.3, 0.0, 0.3])
    for k, want in [(1, [4]), (3, [1, 2, 4]), (4, [1, 2, 3, 4]), (5, [1, 2, 3, 4, 5]),
                    (8, list(range(8)))]:
        assert np.flatnonzero(keep_largest(w, k)).tolist() == want
        assert np.flatnonzero(compiled.keep_largest(w, k, TIE_RTOL)).tolist() == want
    rng = np.random.default_rng(0)
    for v in (np.exp(-60 * rng.random(5000)), rng.random(3000), np.ones(100),
              np.r_[np.zeros(400), rng.random(9)]):
        for k in (1, 7, min(300, v.size), v.size):
            assert compiled.kth_largest(v, k) == np.sort(v)[v.size - k]
