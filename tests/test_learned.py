"""The learned method: network shapes, training, online == offline, files, mirroring, ONNX."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from imuloco.core.mirror import _reflection, mirror, mirror_frames, mirror_pairs
from imuloco.errors import InputError
from imuloco.methods import get_method, load_model
from imuloco.methods.learned.method import ensemble
from imuloco.methods.learned.model import Ensemble, Reconstructor, TorchFK, rotation_from_6d
from imuloco.methods.pose import height_index
from imuloco.methods.training import synthesize
from imuloco.ops.heading import heading_from_hips
from imuloco.ops.kinematics import fk
from imuloco.ops.rotations import from_6d, to_6d

TINY = {"hidden": 24, "layers": 1, "epochs": 8, "batch_size": 8, "window": 40, "lr": 1e-2,
        "draws": 1, "validation": 0.0, "threads": 1}


@pytest.fixture(scope="module")
def tiny_model(sample_db):
    db = sample_db.subset([0, 4, 12])  # a run, a left turn, a walk
    return get_method("learned", **TINY).fit(db, ["right_ankle"], "phone", seed=0)


@pytest.fixture(scope="module")
def test_signals(sample_db):
    ex = synthesize(sample_db.subset([13]), ["right_ankle"], "phone", seed=5)[0]
    return ex.signals[:90]


def test_fit_is_reproducible(sample_db):
    db = sample_db.subset([12])
    state = torch.get_rng_state()
    fits = [get_method("learned", **dict(TINY, epochs=1, seed=s)).fit(db, ["right_ankle"],
                                                                     "phone", seed=0)
            for s in (0, 0, 1)]
    assert torch.equal(torch.get_rng_state(), state)  # the caller's generator is left alone
    a, b, c = (f.get_state()[0] for f in fits)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    assert not np.array_equal(a["net.pose.weight"], c["net.pose.weight"])


def test_forward_shapes():
    net = Reconstructor(6, 6 * 5 + 4, hidden=16, layers=2)
    pose, contact, logvar, h = net(torch.zeros(3, 7, 6))
    assert pose.shape == (3, 7, 34) and contact.shape == (3, 7, 4)
    assert logvar.shape == (3, 7, 1) and h.shape == (2, 3, 16)


def test_torch_fk_and_6d_match_numpy(sample_db):
    m = sample_db.clips[0].slice(0, 5)
    sk = m.skeleton
    six = to_6d(m.rotations)
    mats = rotation_from_6d(torch.as_tensor(six, dtype=torch.float64))
    pos = TorchFK(sk.offsets, sk.parents).double()(mats).numpy()
    ref = fk(from_6d(six), np.zeros(3), sk.offsets, sk.parents)[1]
    np.testing.assert_allclose(pos, ref, atol=1e-6)  # offsets are stored as float32


def test_fit_lowers_training_loss(tiny_model):
    first, last = tiny_model.history_[0], tiny_model.history_[-1]
    assert len(tiny_model.history_) == TINY["epochs"]
    assert last["total"] < first["total"]
    # the joint positions are what it learns in a few epochs (its acceleration term starts
    # near the floor: a still pose misses only the true accelerations)
    assert last["position"] < 0.8 * first["position"]


def test_reconstruct_shapes_and_confidence(tiny_model, test_signals):
    out = tiny_model.predict(test_signals)
    j = tiny_model.skeleton_.num_joints
    assert out.vectors.shape == (90, 6 * j + 4)
    assert out.contacts.shape == (90, 4) and np.all((out.contacts >= 0) & (out.contacts <= 1))
    assert out.sigma.shape == (90,) and np.all(out.sigma > 0)
    motion = tiny_model.reconstruct_signals(test_signals)
    assert motion.num_frames == 90 and np.all(np.isfinite(motion.positions()))


def assert_stream_equals_offline(model, signals):
    """The stream, fed the signals and then the last frame ``delay_frames`` more times, gives
    the offline frames after its first ``delay_frames`` steps."""
    offline = model.reconstruct_signals(signals)
    stream = model.stream()
    d = stream.delay_frames
    fed = np.concatenate([signals, np.repeat(signals[-1:], d, axis=0)])
    rots, roots = zip(*[stream.step(s) for s in fed][d:])
    dots = np.abs(np.sum(np.stack(rots) * offline.rotations, axis=-1))  # same rotation up to sign
    np.testing.assert_allclose(dots, 1.0, atol=1e-5)
    np.testing.assert_allclose(np.stack(roots), offline.root, atol=1e-4)


def test_stream_equals_offline(tiny_model, test_signals):
    assert_stream_equals_offline(tiny_model, test_signals)


@pytest.fixture(scope="module")
def lag_model(sample_db):
    return get_method("learned", **TINY, lag=3, height_smooth=0.0).fit(
        sample_db.subset([0, 12]), ["right_ankle"], "phone", seed=0)


def test_lag_looks_ahead_exactly_lag_frames(lag_model, test_signals):
    base = lag_model.predict(test_signals).vectors
    for t in (20, 50):
        changed = test_signals.copy()
        changed[t + 4:] += 5.0  # frames after t + lag: frame t's pose must not move
        np.testing.assert_allclose(lag_model.predict(changed).vectors[: t + 1], base[: t + 1],
                                   atol=1e-5)
        changed = test_signals.copy()
        changed[t + 3] += 5.0   # frame t + lag: it does
        assert np.abs(lag_model.predict(changed).vectors[t] - base[t]).max() > 1e-3


def test_lag_stream_is_late_by_lag_frames(lag_model, test_signals):
    stream = lag_model.stream()
    assert stream.delay_frames == 3 and stream.delay_ms(lag_model.fps_) == 100.0  # 30 fps
    first = [stream.step(s) for s in test_signals[:3]]
    for rot, root in first:  # the mean pose at the origin until frame 0 is due
        np.testing.assert_allclose(rot, first[0][0])
        np.testing.assert_allclose(root[[0, 2]], 0.0)
    assert_stream_equals_offline(lag_model, test_signals)


def test_the_height_is_smoothed_over_its_radius_and_streams_as_offline(lag_model,
                                                                         test_signals):
    """``height_smooth`` (set after training) averages the root's height over a centred
    window, and nothing else: frame t's height moves with frame t + lag + radius's signals,
    not later ones; the stream waits the radius more and still gives the offline frames."""
    smoothed = copy.deepcopy(lag_model)
    smoothed.height_smooth = 1.0  # radius 3
    (_, sharp), (_, even) = (m.pose_vectors(test_signals) for m in (lag_model, smoothed))
    h = height_index(lag_model.skeleton_)
    jerk = [np.abs(np.diff(v[:, h], 3)).mean() for v in (sharp, even)]
    assert jerk[1] < 0.7 * jerk[0]
    np.testing.assert_array_equal(np.delete(even, h, axis=1), np.delete(sharp, h, axis=1))
    base = smoothed.reconstruct_signals(test_signals)
    for t in (20, 50):
        changed = test_signals.copy()
        changed[t + 7:] += 5.0
        np.testing.assert_allclose(smoothed.reconstruct_signals(changed).root[: t + 1],
                                   base.root[: t + 1], atol=1e-6)
        changed = test_signals.copy()
        changed[t + 6] += 5.0
        assert abs(smoothed.reconstruct_signals(changed).root[t, 1] - base.root[t, 1]) > 1e-5
    assert smoothed.stream().delay_frames == 6
    assert_stream_equals_offline(smoothed, test_signals)
    assert_stream_equals_offline(smoothed, test_signals[:4])  # shorter than the window


def rewrite_params(model, path: Path, **params) -> Path:
    """``model`` saved at ``path`` with its header's hyperparameters updated by ``params``
    (a value None deletes the key), as older versions of imuloco wrote them."""
    import json

    model.save(path, overwrite=True)
    with np.load(path, allow_pickle=False) as z:
        data = {k: z[k] for k in z.files}
    header = json.loads(bytes(data["__header__"]).decode())
    for key, value in params.items():
        if value is None:
            del header["params"][key]
        else:
            header["params"][key] = value
    data["__header__"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    np.savez(path, **data)
    return path


def test_a_file_from_before_the_look_ahead_loads_without_one(lag_model, tmp_path):
    old = load_model(rewrite_params(lag_model, tmp_path / "old.npz", lag=None,
                                    accel_weight=None))
    new = get_method("learned")
    assert (new.lag, new.accel_weight) == (8, 150.0)  # the defaults now
    assert old.lag == 0 and old.stream().delay_frames == 0
    assert old.accel_weight == 30.0  # what it was trained with


def test_save_load_round_trip(tiny_model, test_signals, tmp_path):
    path = tiny_model.save(tmp_path / "m.npz")
    with np.load(path, allow_pickle=False) as z:  # no pickled objects inside
        assert "net.gru.weight_ih_l0" in z.files
    loaded = load_model(path)
    a = tiny_model.reconstruct_signals(test_signals)
    b = loaded.reconstruct_signals(test_signals)
    np.testing.assert_array_equal(a.rotations, b.rotations)
    np.testing.assert_array_equal(a.root, b.root)
    assert loaded.history_ == tiny_model.history_


def test_mirror_is_an_involution_and_reflects_positions(sample_db):
    frames = mirror_frames(sample_db.clips)
    swap = mirror_pairs(sample_db.skeleton)
    assert np.array_equal(swap[swap], np.arange(len(swap)))
    for m in sample_db.clips[::5]:
        mm = mirror(m, frames)
        twice = mirror(mm, frames)
        np.testing.assert_allclose(twice.positions(), m.positions(), atol=1e-3)
        # the mirrored figure's joint k is where the partner of k was, reflected
        pos = m.positions()
        hips = pos[0, [m.skeleton.part("left_hip"), m.skeleton.part("right_hip")]]
        ref = _reflection(float(heading_from_hips(hips[0], hips[1])))
        want = (pos[:, swap] - m.root[0]) @ ref.T + m.root[0]
        np.testing.assert_allclose(mm.positions(), want, atol=5e-3)


def test_mirror_turns_left_turns_into_right_turns(sample_db):
    m = sample_db.where(content="walk-turn-left").clips[0]
    yaw = np.unwrap(heading_from_hips(*m.part_positions(["left_hip", "right_hip"]).swapaxes(0, 1)))
    mm = mirror(m)
    yaw_m = np.unwrap(heading_from_hips(*mm.part_positions(["left_hip", "right_hip"])
                                        .swapaxes(0, 1)))
    assert abs(yaw[-1] - yaw[0]) > 0.5
    np.testing.assert_allclose(yaw_m[-1] - yaw_m[0], -(yaw[-1] - yaw[0]), atol=0.05)


def test_mirrored_model_twice_is_the_model(tiny_model, sample_db, test_signals):
    left = tiny_model.mirrored(sample_db.clips[:4])
    assert left.placements_ == ["left_ankle"]
    # the protocol of the weights travels with them
    assert left.protocol_["clips"] == tiny_model.protocol_["clips"]
    assert left.protocol_["mirrored_from"] == ["right_ankle"]
    back = left.mirrored(sample_db.clips[:4])
    np.testing.assert_array_equal(back.input_map_, tiny_model.input_map_)
    a = tiny_model.predict(test_signals).vectors
    b = back.predict(test_signals).vectors
    np.testing.assert_allclose(a, b, atol=1e-6)
    # the left model reads a left-ankle recording and mirrors its output consistently
    v = left.predict(test_signals).vectors
    np.testing.assert_allclose(left._mirror_vectors(left._mirror_vectors(v)), v, atol=1e-6)


def test_onnx_export(tiny_model, tiny_ensemble, sample_db, test_signals, tmp_path):
    onnx = pytest.importorskip("onnx")
    from scipy.signal import lfilter

    from imuloco.methods.learned.export import export_onnx

    left = tiny_model.mirrored(sample_db.clips[:4])
    for k, model in enumerate((tiny_model, left, tiny_ensemble[0])):
        path = export_onnx(model, tmp_path / f"{k}.onnx")
        proto = onnx.load(str(path))
        onnx.checker.check_model(proto)
        meta = {p.key: p.value for p in proto.metadata_props}
        assert meta["method"] == "learned" and model.placements_[0] in meta["placements"]
        ort = pytest.importorskip("onnxruntime")
        sess = ort.InferenceSession(str(path))
        h = np.zeros(json.loads(meta["h_shape"]), np.float32)
        assert h.shape == (model.members * model.layers, 1, model.hidden)
        lag = int(meta["lag"])
        assert lag == model.lag == 8
        np.testing.assert_allclose(json.loads(meta["height_weights"]), model.height_weights,
                                   atol=1e-9)
        fed = np.concatenate([test_signals, np.repeat(test_signals[-1:], lag, axis=0)])
        pose_, contacts, sigma, _, novelty, spread = sess.run(
            None, {"signals": fed[None].astype(np.float32), "h": h})
        ref = model.predict(test_signals)  # output frame k is input frame k - lag
        np.testing.assert_allclose(pose_[0, lag:], ref.vectors, atol=2e-3)
        np.testing.assert_allclose(contacts[0, lag:], ref.contacts, atol=1e-4)
        np.testing.assert_allclose(sigma[0, lag:], ref.sigma, rtol=1e-4)
        if ref.spread is None:
            assert np.isnan(spread).all()
        else:
            np.testing.assert_allclose(spread[0, lag:], ref.spread, rtol=2e-3, atol=1e-5)
        # the host's smoothing of the documented recursion gives the model's own novelty
        a = float(meta["novelty_alpha"])
        smooth = lfilter([a], [1, -(1 - a)], novelty[0].astype(np.float64),
                         zi=[(1 - a) * novelty[0, 0]])[0]
        np.testing.assert_allclose(smooth[lag:], ref.novelty, rtol=1e-3)
        assert float(meta["novelty_threshold"]) == model.novelty_threshold_


def test_cli_train_any_method(tmp_path):
    from click.testing import CliRunner

    from imuloco.cli import cli

    out = tmp_path / "mean.npz"
    res = CliRunner().invoke(cli, ["train", "--method", "mean", "--split", "random-clips",
                                   "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert load_model(out).name == "mean"
    res = CliRunner().invoke(cli, ["train", "--method", "learned", "--param", "epochs=1",
                                   "--param", "hidden=8", "--param", "layers=1",
                                   "--param", "draws=0", "--limit", "3", "-o",
                                   str(tmp_path / "l.npz")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "l.npz.history.json").exists()
    res = CliRunner().invoke(cli, ["export-onnx", "--model", str(tmp_path / "l.npz"), "-o",
                                   str(tmp_path / "l.onnx")])
    assert res.exit_code == 0, res.output


def test_package_imports_without_torch():
    import subprocess
    import sys

    code = (
        "import importlib.abc, sys\n"
        "class Block(importlib.abc.MetaPathFinder):\n"
        "    def find_spec(self, name, path, target=None):\n"
        "        if name == 'torch' or name.startswith('torch.'):\n"
        "            raise ModuleNotFoundError(\"No module named 'torch'\", name='torch')\n"
        "sys.meta_path.insert(0, Block())\n"
        "import imuloco.methods, imuloco.cli, imuloco.core.mirror\n"
        "found = imuloco.methods.available_methods()\n"
        "assert 'learned' not in found and 'mean' in found\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert res.returncode == 0, res.stderr


def test_the_held_out_clips_are_found_without_torch():
    """The benchmarks pick the clips a shipped model never saw without loading torch."""
    import subprocess
    import sys

    code = ("import sys\n"
            "from imuloco.methods.training import VALIDATION_SHARE, held_out, held_out_clips\n"
            "assert 'torch' not in sys.modules, 'torch imported'\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert res.returncode == 0, res.stderr


def test_files_with_retired_features_load_or_are_refused(tiny_model, test_signals, tmp_path):
    from imuloco.errors import ModelFileError

    # the shipped files' kind: features="raw" (and its unused tau) in the header
    old = load_model(rewrite_params(tiny_model, tmp_path / "raw.npz", features="raw", tau=3.0))
    np.testing.assert_array_equal(old.predict(test_signals).vectors,
                                  tiny_model.predict(test_signals).vectors)
    path = rewrite_params(tiny_model, tmp_path / "centered.npz", features="centered", tau=2.0)
    with pytest.raises(ModelFileError, match=r"centered\.npz.*features='centered'.*retrain"):
        load_model(path)


@pytest.fixture(scope="module")
def tiny_ensemble(tiny_model, sample_db):
    """tiny_model and a second fit from another seed, as an ensemble."""
    db = sample_db.subset([0, 4, 12])
    other = get_method("learned", **dict(TINY, seed=1)).fit(db, ["right_ankle"], "phone", seed=0)
    return ensemble([tiny_model, other]), other


def test_an_ensemble_averages_its_members(tiny_ensemble, tiny_model, test_signals):
    model, other = tiny_ensemble
    # each member standardizes its own augmented draws: the ensemble maps between them
    assert not np.allclose(tiny_model.x_mean_, other.x_mean_)
    a, b, e = (m.predict(test_signals) for m in (tiny_model, other, model))
    assert not np.allclose(a.vectors, b.vectors, atol=1e-2)
    np.testing.assert_allclose(e.vectors, (a.vectors + b.vectors) / 2, atol=1e-5)
    np.testing.assert_allclose(e.contacts, (a.contacts + b.contacts) / 2, atol=1e-6)
    np.testing.assert_allclose(e.sigma ** 2, (a.sigma ** 2 + b.sigma ** 2) / 2, rtol=1e-5)
    # novelty: the members' mean, each against its own reference
    np.testing.assert_allclose(e.novelty, (a.novelty + b.novelty) / 2, rtol=1e-4)
    assert model.novelty_threshold_ == pytest.approx(
        (tiny_model.novelty_threshold_ + other.novelty_threshold_) / 2)
    assert_stream_equals_offline(model, test_signals)
    assert a.spread is None and b.spread is None


def member_positions(model, vectors):
    """Root-relative joint positions (T, J, 3) of pose vectors' local rotations (numpy)."""
    sk = model.skeleton_
    j = sk.num_joints
    rot = from_6d(vectors[:, : 6 * j].reshape(len(vectors), j, 6))
    return fk(rot, np.zeros((len(vectors), 3)), sk.offsets, sk.parents)[1]


def test_an_ensembles_spread_is_its_members_disagreement(tiny_ensemble, tiny_model,
                                                        test_signals, tmp_path):
    model, other = tiny_ensemble
    a, b, e = (m.predict(test_signals) for m in (tiny_model, other, model))
    pa, pb = member_positions(model, a.vectors), member_positions(model, b.vectors)
    # two members: each joint's variance (over K - 1) is half their squared distance
    want = np.sqrt((np.sum((pa - pb)[:, 1:] ** 2, axis=-1) / 2).mean(axis=1))
    np.testing.assert_allclose(e.spread, want, rtol=1e-3, atol=1e-6)
    assert e.spread.min() > 1e-4
    same = ensemble([tiny_model, tiny_model]).predict(test_signals)  # members that agree
    np.testing.assert_allclose(same.spread, 0.0, atol=1e-5)
    # a calibration may use it, and the stream computes it as offline
    cal = {"coef": [0.1, 1.0, 0.2, 0.5], "scores": ["sigma_m", "novelty", "spread_m"],
           "source": "t"}
    calibrated = load_model(model.save(tmp_path / "e.npz"))
    calibrated.set_calibration(cal)
    full = calibrated.reconstruct_signals_full(test_signals)
    assert set(full.scores) == {"sigma_m", "novelty", "spread_m"}
    np.testing.assert_allclose(full.error_m, np.exp(0.1) * e.sigma * e.novelty ** 0.2
                               * e.spread ** 0.5, rtol=1e-6)
    stream = calibrated.stream()
    d = stream.delay_frames
    errs = []
    for s in np.concatenate([test_signals, np.repeat(test_signals[-1:], d, axis=0)]):
        stream.step(s)
        errs.append(getattr(stream, "error_m", np.nan))
    np.testing.assert_allclose(errs[d:], full.error_m, rtol=1e-4)
    with pytest.raises(InputError, match="spread_m needs an ensemble"):
        tiny_model.set_calibration(cal)


def test_stacked_members_equal_their_modules():
    """In inference an ensemble runs its members' weights stacked (a GRU written out over
    them); in training mode the members' own torch modules: the same outputs, whole sequences
    or frame by frame with the state carried, and new weights are seen."""
    torch.manual_seed(0)
    net = Ensemble.of_size(3, 6, 34, hidden=16, layers=2)
    x, h = torch.randn(2, 9, 6), 0.5 * torch.randn(6, 2, 16)
    with torch.no_grad():
        want = net.train()(x, h)
        whole = net.eval()(x, h)
        hs, frames = h, []
        for t in range(9):
            *out, hs = net(x[:, t:t + 1], hs)
            frames.append(out)
        stepped = [torch.cat(v, dim=1) for v in zip(*frames)] + [hs]
        for got in (whole, stepped):
            for a, b in zip(want, got, strict=True):
                np.testing.assert_allclose(b.numpy(), a.numpy(), atol=1e-5)
        other = Ensemble.of_size(3, 6, 34, hidden=16, layers=2)
        net.load_state_dict(other.state_dict())
        np.testing.assert_allclose(net(x, h)[0].numpy(), other.train()(x, h)[0].numpy(),
                                   atol=1e-5)


def test_a_long_sequence_runs_each_member_once_with_the_stacked_result():
    """Past STACKED_FRAMES frames an ensemble in inference runs each member's own GRU over the
    whole sequence (one call each): the stacked weights' outputs and state to float
    precision."""
    from imuloco.methods.learned.model import STACKED_FRAMES

    torch.manual_seed(1)
    net = Ensemble.of_size(3, 6, 34, hidden=16, layers=2).eval()
    x, h = torch.randn(2, 3 * STACKED_FRAMES, 6), 0.5 * torch.randn(6, 2, 16)
    with torch.no_grad():
        feats, hn = net.encode(x, h)
        stacked = net._weights().encode(x, h)
    np.testing.assert_allclose(feats.numpy(), stacked[0].numpy(), atol=1e-5)
    np.testing.assert_allclose(hn.numpy(), stacked[1].numpy(), atol=1e-5)


def test_member_spread_in_pieces_is_the_spread_in_one(sample_db, monkeypatch):
    from imuloco.methods.learned import ensemble as ens

    sk = sample_db.clips[0].skeleton
    rng = np.random.default_rng(0)
    vectors = rng.normal(0, 1, (50, 4, 6 * sk.num_joints + 4))
    monkeypatch.setattr(ens, "SPREAD_FRAMES", 7)
    pieces = ens.member_spread(vectors, sk)
    monkeypatch.setattr(ens, "SPREAD_FRAMES", 1000)
    np.testing.assert_array_equal(pieces, ens.member_spread(vectors, sk))
    assert pieces.shape == (50,) and (pieces > 0).all()


def test_an_ensemble_file_round_trip_and_mirror(tiny_ensemble, sample_db, test_signals,
                                                tmp_path):
    model, _other = tiny_ensemble
    model.save(tmp_path / "e.npz")
    back = load_model(tmp_path / "e.npz")
    assert back.members == 2 and [p["model_seed"] for p in back.protocol_["members"]] == [0, 1]
    np.testing.assert_array_equal(back.predict(test_signals).vectors,
                                  model.predict(test_signals).vectors)
    assert back.novelty_threshold_ == model.novelty_threshold_
    left = model.mirrored(sample_db.clips[:4])
    assert left.members == 2 and left.placements_ == ["left_ankle"]
    again = left.mirrored(sample_db.clips[:4])
    np.testing.assert_allclose(again.predict(test_signals).vectors,
                               model.predict(test_signals).vectors, atol=1e-6)


def test_members_train_as_separate_fits_would(sample_db, test_signals):
    db = sample_db.subset([12])
    one = dict(TINY, epochs=1)
    both = get_method("learned", **one, members=2).fit(db, ["right_ankle"], "phone", seed=0)
    apart = ensemble([get_method("learned", **dict(one, seed=s)).fit(db, ["right_ankle"],
                                                                     "phone", seed=0)
                      for s in (0, 1)])
    np.testing.assert_array_equal(both.predict(test_signals).vectors,
                                  apart.predict(test_signals).vectors)
    assert {h["member"] for h in both.history_} == {0, 1}
    np.testing.assert_array_equal(both.predict(test_signals).novelty,
                                  apart.predict(test_signals).novelty)


def test_an_ensemble_refuses_members_that_differ(tiny_model, sample_db):
    db = sample_db.subset([12])
    lagged = get_method("learned", **dict(TINY, epochs=1, lag=2)).fit(db, ["right_ankle"],
                                                                      "phone", seed=0)
    with pytest.raises(InputError, match=r"member 1 differs from member 0 in lag \(2 vs 8\)"):
        ensemble([tiny_model, lagged])
    two = get_method("learned", **dict(TINY, epochs=1)).fit(db, ["right_ankle", "right_wrist"],
                                                           "phone", seed=0)
    with pytest.raises(InputError, match=r"member 1 differs .*placements_.*input_map_"):
        ensemble([tiny_model, two])
    with pytest.raises(InputError, match="at least 2"):
        ensemble([tiny_model])
    mean = get_method("mean").fit(db, ["right_ankle"], "phone", seed=0)
    with pytest.raises(InputError, match="member 1: expected a learned model"):
        ensemble([tiny_model, mean])


def test_cli_ensemble(tmp_path):
    from click.testing import CliRunner

    from imuloco.cli import cli

    tiny = ["--param", "epochs=1", "--param", "hidden=8", "--param", "layers=1", "--param",
            "draws=1", "--limit", "3"]
    for s in (0, 1):
        res = CliRunner().invoke(cli, ["train", "--method", "learned", *tiny, "--param",
                                       f"seed={s}", "-o", str(tmp_path / f"m{s}.npz")])
        assert res.exit_code == 0, res.output
    out, left = tmp_path / "e.npz", tmp_path / "left.npz"
    args = ["ensemble", str(tmp_path / "m0.npz"), str(tmp_path / "m1.npz"), "--limit", "3"]
    res = CliRunner().invoke(cli, [*args, "-o", str(out), "--mirrored", str(left)])
    assert res.exit_code == 0, res.output
    model = load_model(out)
    assert model.members == 2 and model.novelty_mean_ is not None
    assert load_model(left).placements_ == ["left_ankle"]
    assert (tmp_path / "e.npz.curves.png").exists()
    before = out.read_bytes()
    res = CliRunner().invoke(cli, [*args, "-o", str(out)])  # nothing the user has is replaced
    assert res.exit_code != 0 and "exists" in res.output and out.read_bytes() == before
    res = CliRunner().invoke(cli, ["ensemble", str(tmp_path / "m0.npz"), str(out), "-o",
                                   str(tmp_path / "x.npz")])
    assert res.exit_code == 2 and "member 1: expected a learned model of one network" in res.output


def test_held_out_clips_are_the_clips_a_fit_validates_on(sample_db):
    """The benchmarks' "lab" set is exactly the clips a fit leaves out of training."""
    from imuloco.methods.learned.method import Learned
    from imuloco.methods.training import held_out_clips, synthesize

    share = 0.3
    examples = synthesize(sample_db, ["right_ankle"], "phone", seed=0)
    _, val = Learned(validation=share)._validation_split(examples)
    held = held_out_clips(sample_db, share)
    assert 0 < len(held) < len(sample_db)
    assert [c["name"] for c in held.labels] == [e.labels["name"] for e in val]
    assert len(held_out_clips(sample_db)) < len(held)  # the default share is smaller


def test_held_out_clips_default_share_is_the_fits_default(sample_db, monkeypatch):
    """Without a share, the clips are held out by the share a default fit validates on."""
    from imuloco.methods import training
    from imuloco.methods.learned.method import Learned

    assert Learned().validation == training.VALIDATION_SHARE
    shares = []
    monkeypatch.setattr(training, "held_out", lambda name, share: shares.append(share) or False)
    training.held_out_clips(sample_db)
    assert shares == [Learned().validation] * len(sample_db)


def test_a_model_keeps_the_pitch_of_a_flat_foot_it_learned(sample_db, tiny_model, tmp_path):
    from imuloco.phases.contacts import flat_foot_pitch

    db = sample_db.subset([0, 4, 12])  # tiny_model's motions
    assert tiny_model.flat_pitch_ == flat_foot_pitch(db.clips)
    assert load_model(tiny_model.save(tmp_path / "m.npz")).flat_pitch_ == tiny_model.flat_pitch_
    # a file from before it: the lock holds a flat foot at the pitch it lands with
    path = tiny_model.save(tmp_path / "old.npz")
    with np.load(path, allow_pickle=False) as z:
        data = {k: z[k] for k in z.files}
    header = json.loads(bytes(data["__header__"]).decode())
    del header["values"]["flat_pitch"]
    data["__header__"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    np.savez(path, **data)
    assert load_model(path).flat_pitch_ is None
    # a file that says something else is refused by name, with the file
    from imuloco.errors import ModelFileError

    for wrong in ("flat", 4.0, [0.1]):
        header["values"]["flat_pitch"] = wrong
        data["__header__"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
        np.savez(path, **data)
        with pytest.raises(ModelFileError, match=r"old\.npz.*flat_pitch"):
            load_model(path)


def test_novelty_in_pieces_is_the_novelty_in_one(monkeypatch):
    """The novelty's distances go NOVELTY_FRAMES frames at a time: the same smoothed novelty
    (the shipped ensemble's reference, features drawn around it) as in one product."""
    from imuloco.app.pipeline import shipped_model
    from imuloco.methods import load_model
    from imuloco.methods.learned import confidence

    model = load_model(shipped_model("learned", "right_ankle"))
    rng = np.random.default_rng(0)
    feats = (model.novelty_mean_ + rng.normal(0, 0.3, (5000, len(model.novelty_mean_))))
    monkeypatch.setattr(confidence, "NOVELTY_FRAMES", 10**9)
    one = model._novelty(feats)
    monkeypatch.setattr(confidence, "NOVELTY_FRAMES", 2048)
    np.testing.assert_allclose(model._novelty(feats.astype(np.float32)),
                               model._novelty(feats.astype(np.float32).astype(np.float64)),
                               rtol=0, atol=0)
    np.testing.assert_allclose(model._novelty(feats), one, rtol=1e-12)
