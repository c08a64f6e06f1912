"""Issue 16's confidence: body-proportion augmentation, the novelty flag, the bidirectional
variant, the calibration of the predicted error and the ``calibrate`` command."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from click.testing import CliRunner

from imuloco.cli import cli
from imuloco.errors import ImulocoError
from imuloco.lab import confidence as conf
from imuloco.methods import get_method, load_model
from imuloco.methods.base import calibrated_error
from imuloco.methods.learned.train import proportioned
from imuloco.methods.training import synthesize

TINY = {"hidden": 16, "layers": 1, "epochs": 3, "batch_size": 8, "window": 40, "lr": 1e-2,
        "draws": 1, "validation": 0.0, "threads": 1}


@pytest.fixture(scope="module")
def tiny(sample_db):
    return get_method("learned", **TINY).fit(sample_db.subset([0, 12]), ["right_ankle"],
                                             "phone", seed=0)


@pytest.fixture(scope="module")
def signals(sample_db):
    return synthesize(sample_db.subset([13]), ["right_ankle"], "phone", seed=5)[0].signals[:80]


def test_proportioned_scales_limbs_and_keeps_rotations(sample_db):
    m = sample_db.clips[0]
    assert proportioned(m, np.random.default_rng(0), 0.0) is m
    p = proportioned(m, np.random.default_rng(0), 0.2)
    rng = np.random.default_rng(0)
    height = rng.uniform(0.8, 1.2)
    legs, arms, trunk = rng.uniform(0.9, 1.1, 3)
    sk, sp = m.skeleton, p.skeleton
    np.testing.assert_array_equal(p.rotations, m.rotations)
    knee, elbow = sk.part("right_knee"), sk.part("left_elbow")
    np.testing.assert_allclose(sp.offsets[knee], sk.offsets[knee] * height * legs)
    np.testing.assert_allclose(sp.offsets[elbow], sk.offsets[elbow] * height * arms)
    np.testing.assert_allclose(sp.offsets[sk.part("chest")], sk.offsets[sk.part("chest")]
                               * height * trunk)
    np.testing.assert_allclose(p.root, m.root * height * legs)


def test_strap_draws_are_worn_on_a_strap_and_none_without(sample_db, monkeypatch):
    """``strap``: that share of augmented draws is simulated on a random soft-tissue strap;
    without it the draws are the rigid ones, sample for sample."""
    import imuloco.methods.learned.train as tr
    from imuloco.methods.training import synthesize
    from imuloco.sensors.strap import Strap

    base = synthesize(sample_db.subset([0, 12]), ["right_ankle"], "phone", seed=0)
    args = (["right_ankle"], "phone", 0, 2, 0.15, 2.0, False)
    rigid, again = tr.augment(base, *args), tr.augment(base, *args, strap=0.0)
    for a, b in zip(rigid[2:], again[2:]):
        np.testing.assert_array_equal(a.signals, b.signals)
    worn = []
    simulate = tr.simulate

    def spy(*a, **kw):
        worn.append(a[5] if len(a) > 5 else kw.get("strap"))
        return simulate(*a, **kw)

    monkeypatch.setattr(tr, "simulate", spy)
    for share, expect in ((1.0, 4), (0.0, 0)):
        worn.clear()
        tr.augment(base, *args, strap=share)
        assert sum(isinstance(w, Strap) for w in worn) == expect and len(worn) == 4


def test_inclined_reads_a_sensor_turned_about_its_x_axis(sample_db):
    """``incline``: the augmented signals are those of a sensor strapped turned about its
    medio-lateral axis, simulated so (clean); the draws without it are unchanged."""
    import imuloco.methods.learned.train as tr
    from imuloco.sensors.placement import get_placement
    from imuloco.sensors.simulate import simulate

    m = sample_db.clips[12]
    ankle = get_placement("right_ankle")
    a = np.deg2rad(15.0)
    turned = ankle.perturbed(np.array([np.sin(a / 2), 0, 0, np.cos(a / 2)]), np.zeros(3))
    want = simulate(m, [turned, "right_ankle"])
    got = tr.inclined(simulate(m, ["right_ankle", "right_ankle"]), [15.0, 0.0])
    np.testing.assert_allclose(got.acc[:, 0], want.acc[:, 0], atol=1e-6)
    np.testing.assert_allclose(got.gyro[:, 0], want.gyro[:, 0], atol=1e-9)
    np.testing.assert_allclose(got.orientation[:, 0], want.orientation[:, 0], atol=1e-9)
    np.testing.assert_array_equal(got.acc[:, 1], want.acc[:, 1])
    assert np.abs(got.acc[:, 0] - want.acc[:, 1]).max() > 1.0  # turned: other readings

    base = synthesize(sample_db.subset([0, 12]), ["right_ankle"], "phone", seed=0)
    args = (["right_ankle"], "phone", 0, 2, 0.15, 2.0, False)
    plain, tilted = tr.augment(base, *args), tr.augment(base, *args, incline=20.0)
    for a_, b_ in zip(plain[:2], tilted[:2]):  # the benchmark's own draws are kept
        np.testing.assert_array_equal(a_.signals, b_.signals)
    for a_, b_ in zip(plain[2:], tilted[2:]):
        assert not np.allclose(a_.signals, b_.signals)
        # a rotation: the specific force's norm is the same, sample for sample
        np.testing.assert_allclose(np.linalg.norm(a_.signals[:, :3], axis=1),
                                   np.linalg.norm(b_.signals[:, :3], axis=1), rtol=1e-4)


def test_novelty_grows_with_the_distance_from_training_features(tiny):
    w = tiny.novelty_mean_.shape[0]
    at_mean = tiny._novelty(np.tile(tiny.novelty_mean_, (30, 1)))
    np.testing.assert_allclose(at_mean, 0.0, atol=1e-9)
    step = np.linalg.cholesky(np.linalg.inv(tiny.novelty_precision_))[:, 0]  # one sd along
    far = [tiny._novelty(np.tile(tiny.novelty_mean_ + k * step, (30, 1)))[-1] for k in (1, 2)]
    np.testing.assert_allclose(far[1] / far[0], 4.0, rtol=1e-6)  # a squared distance
    np.testing.assert_allclose(far[0], 1.0 / w / tiny.novelty_scale_, rtol=1e-6)


def test_confidence_of_reconstruction_stream_and_file(tiny, signals, tmp_path):
    full = tiny.reconstruct_signals_full(signals)
    assert full.error_m.shape == (80,) and np.all(full.error_m > 0)
    np.testing.assert_array_equal(full.error_m, full.scores["sigma_m"])  # not calibrated
    np.testing.assert_array_equal(full.unreliable,
                                  full.scores["novelty"] > tiny.novelty_threshold_)
    assert "not calibrated" in full.note
    stream = tiny.stream()
    d = stream.delay_frames
    fed = np.concatenate([signals, np.repeat(signals[-1:], d, axis=0)])
    errs = []
    for s in fed:
        stream.step(s)
        errs.append(stream.error_m)
    np.testing.assert_allclose(errs[d:], full.error_m, rtol=1e-5)
    loaded = load_model(tiny.save(tmp_path / "m.npz"))
    again = loaded.reconstruct_signals_full(signals)
    np.testing.assert_array_equal(again.error_m, full.error_m)
    np.testing.assert_array_equal(again.unreliable, full.unreliable)


def test_a_calibration_is_applied_saved_and_checked(tiny, signals, tmp_path):
    cal = {"coef": [np.log(2.0), 1.0, 0.5], "scores": ["sigma_m", "novelty"], "source": "t"}
    model = load_model(tiny.save(tmp_path / "m.npz"))
    model.set_calibration(cal)
    full = model.reconstruct_signals_full(signals)
    s = full.scores
    np.testing.assert_allclose(full.error_m, 2.0 * s["sigma_m"] * s["novelty"] ** 0.5)
    assert "calibrated on t" in full.note
    again = load_model(model.save(tmp_path / "c.npz"))
    np.testing.assert_allclose(again.reconstruct_signals_full(signals).error_m, full.error_m)
    for wrong in ({"coef": [0.0, 1.0], "scores": ["sigma_m", "novelty"]},  # coef short
                  {"coef": [0.0, 1.0], "scores": ["height"]},
                  {"coef": [0.0], "scores": []}):
        with pytest.raises(ImulocoError, match="scores"):
            model.set_calibration(wrong)
    model.set_calibration({"coef": [0.0, 1.0], "scores": ["sigma_m"], "source": "t"})
    np.testing.assert_allclose(model.reconstruct_signals_full(signals).error_m, s["sigma_m"])
    with pytest.raises(ImulocoError, match="no per-frame error"):
        get_method("ridge").set_calibration(cal)


def test_bidirectional_looks_both_ways_and_is_offline_only(sample_db, signals):
    bi = get_method("learned", **TINY, bidirectional=True).fit(sample_db.subset([12]),
                                                               ["right_ankle"], "phone", seed=0)
    assert bi.lookahead == 0
    a = bi.predict(signals).vectors
    late = signals.copy()
    late[60:] += 5.0
    b = bi.predict(late).vectors
    assert not np.allclose(a[:30], b[:30])  # the end of the recording changes its start
    with pytest.raises(NotImplementedError, match="offline"):
        bi.stream()
    assert bi.reconstruct_signals(signals).num_frames == 80
    # the bench measures it without an online step (it tried to stream it and failed), and
    # live refuses it by name before it starts
    from imuloco.app.live.session import LiveSession
    from imuloco.errors import InputError
    from imuloco.lab.bench import _latency

    assert not bi.can_stream() and bi.supports_online
    assert _latency(bi, signals) == (None, None, None)
    with pytest.raises(InputError, match="bidirectional"):
        LiveSession(bi)


def rows(n_per: int = 400, seed: int = 0) -> conf.Rows:
    """Synthetic per-frame rows: actual = 0.03 * sigma**0.5 * novelty**0.8 * noise."""
    rng = np.random.default_rng(seed)
    n = 3 * n_per
    sigma = rng.uniform(0.01, 0.08, n)
    novelty = rng.uniform(0.5, 6.0, n)
    actual = 0.03 * sigma ** 0.5 * novelty ** 0.8 * np.exp(rng.normal(0, 0.05, n))
    return {"actual_m": actual, "error_m": sigma, "unreliable": novelty > 5.0,
            "clip": np.repeat(["a", "b", "c"], n_per), "content": np.repeat(["walk", "run",
                                                                             "dash"], n_per),
            "fold": np.repeat(["walk", "run", "dash"], n_per), "seed": np.zeros(n, int),
            "score_sigma_m": sigma, "score_novelty": novelty}


def test_fit_recovers_the_law_and_matches_the_rms():
    r = rows()
    cal = conf.fit(r, "synthetic")
    assert cal["scores"] == ["novelty", "sigma_m"]
    np.testing.assert_allclose(cal["coef"][1:], [0.8, 0.5], atol=0.02)
    pred = calibrated_error(cal, {"sigma_m": r["score_sigma_m"], "novelty": r["score_novelty"]})
    np.testing.assert_allclose(np.mean(pred ** 2), np.mean(r["actual_m"] ** 2), rtol=1e-6)
    table = {t["content"]: t for t in conf.check(r, pred)}
    assert all(t["within"] for t in table.values())
    raw = {t["content"]: t for t in conf.check(r)}  # the uncalibrated sigma is far off
    assert not raw["all"]["within"]
    assert raw["all"]["ratio"] == pytest.approx(
        np.sqrt(np.mean(r["score_sigma_m"] ** 2) / np.mean(r["actual_m"] ** 2)), abs=1e-3)


def test_crossfit_never_uses_a_group_s_own_frames():
    r = rows()
    run = r["content"] == "run"
    r["actual_m"] = np.where(run, 10 * r["actual_m"], r["actual_m"])  # run: another law
    crossed = conf.crossfit(r)
    others = conf.fit({k: v[~run] for k, v in r.items()}, "others")
    np.testing.assert_allclose(crossed[run], calibrated_error(
        others, {"sigma_m": r["score_sigma_m"][run], "novelty": r["score_novelty"][run]}))
    table = {t["content"]: t for t in conf.check(r, crossed)}
    assert table["run"]["ratio"] < 0.2  # run's own frames would have fitted it


def test_bench_writes_confidence_and_calibrate_uses_it(tmp_path):
    out = tmp_path / "bench"
    spec = "learned[hidden=8;layers=1;epochs=1;draws=0;window=40;threads=1]"
    res = CliRunner().invoke(cli, ["bench", "--method", spec, "--split", "heldout-contents",
                                   "--out", str(out)])
    assert res.exit_code == 0, res.output
    (npz,) = out.glob("confidence-*.npz")
    with np.load(npz, allow_pickle=False) as z:
        assert set(conf.COLUMNS) <= set(z.files)
        assert {"score_sigma_m", "score_novelty"} <= set(z.files)
        per_clip = json.loads((out / "per_clip.json").read_text())
        assert len(z["actual_m"]) == sum(c["n_frames"] for c in per_clip)
        assert set(z["content"]) == {c["motion_type"] for c in per_clip}
    model = tmp_path / "m.npz"
    res = CliRunner().invoke(cli, ["train", "--method", "learned", "--param", "epochs=1",
                                   "--param", "hidden=8", "--param", "layers=1",
                                   "--param", "draws=0", "--limit", "3", "-o", str(model)])
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(cli, ["calibrate", str(out), "--model", str(model), "-o",
                                   str(model)])
    assert res.exit_code != 0 and "input" in res.output  # never in place
    res = CliRunner().invoke(cli, ["calibrate", str(out), "--model", str(model), "-o",
                                   str(tmp_path / "c.npz"), "--out", str(tmp_path / "cal")])
    assert res.exit_code == 0, res.output
    assert "calibrated on the other contents" in res.output
    cal = json.loads((tmp_path / "cal" / "confidence.json").read_text())["calibration"]
    assert load_model(tmp_path / "c.npz").calibration_ == cal
    res = CliRunner().invoke(cli, ["calibrate", str(tmp_path)])
    assert res.exit_code != 0 and "no confidence-*.npz" in res.output
    # an ensemble's rows add its members' spread, which one network cannot give
    ens = tmp_path / "ens"
    res = CliRunner().invoke(cli, ["bench", "--method", spec.replace("]", ";members=2]"),
                                   "--split", "heldout-contents", "--out", str(ens)])
    assert res.exit_code == 0, res.output
    (npz,) = ens.glob("confidence-*.npz")
    with np.load(npz, allow_pickle=False) as z:
        assert z["score_spread_m"].min() > 0
    res = CliRunner().invoke(cli, ["calibrate", str(ens), "--model", str(model), "-o",
                                   str(tmp_path / "d.npz")])
    assert res.exit_code != 0 and "spread_m needs an ensemble" in res.output
    res = CliRunner().invoke(cli, ["calibrate", str(ens), "--check", str(out)])
    assert res.exit_code != 0 and "no score ['spread_m']" in res.output
    # cross-dataset rows also carry the error against the truth on the training skeleton
    cross = tmp_path / "cross"
    cross.mkdir()
    with np.load(next(out.glob("confidence-*.npz")), allow_pickle=False) as z:
        rows = {k: z[k] for k in z.files}
    np.savez(cross / "confidence-learned.npz", **rows, actual_retargeted_m=rows["actual_m"] / 2)
    res = CliRunner().invoke(cli, ["calibrate", str(out), "--check", str(cross)])
    assert res.exit_code == 0, res.output
    title = "against the truth retargeted onto the training skeleton"
    halves = [line for line in res.output.split(title)[1].splitlines() if "| all |" in line]
    whole = [line for line in res.output.split(title)[0].splitlines() if "| all |" in line]
    half_cm, whole_cm = (float(lines[-1].split("|")[3]) for lines in (halves, whole))
    assert half_cm == pytest.approx(whole_cm / 2, abs=0.01)


def test_train_writes_the_mirrored_model(tmp_path):
    right, left = tmp_path / "r.npz", tmp_path / "l.npz"
    res = CliRunner().invoke(cli, ["train", "--method", "learned", "--param", "epochs=1",
                                   "--param", "hidden=8", "--param", "layers=1", "--param",
                                   "draws=0", "--limit", "3", "-o", str(right), "--mirrored",
                                   str(left)])
    assert res.exit_code == 0, res.output
    assert load_model(left).placements_ == ["left_ankle"]
    assert load_model(left).protocol_["mirrored_from"] == ["right_ankle"]
    res = CliRunner().invoke(cli, ["train", "--method", "mean", "-o", str(tmp_path / "m.npz"),
                                   "--mirrored", str(tmp_path / "n.npz")])
    assert res.exit_code != 0 and "only learned" in res.output


def test_a_model_without_novelty_measures_it_on_its_training_motions(tiny, sample_db, signals):
    from imuloco.methods.training import TrainingSet

    arrays, values = tiny.get_state()
    for k in ("novelty_mean", "novelty_precision"):
        arrays.pop(k)
    old = get_method("learned", **TINY)
    old.set_setup(tiny.skeleton_, tiny.fps_, tiny.placements_, tiny.noise_)
    old.set_state(arrays, values)  # as a file from before novelty loads
    full = old.reconstruct_signals_full(signals)
    assert full.unreliable is None and "before novelty" in full.note
    data = TrainingSet.synthesize(sample_db.subset([0, 12]), ["right_ankle"], "phone", 0)
    old.measure_novelty(data)
    assert old.novelty_threshold_ > 1.0  # the 99th percentile over the median
    # about 1 on the motions it was measured on, by construction (the median is the scale)
    novelty = np.concatenate([old.predict(e.signals).novelty for e in data.examples])
    assert np.median(novelty) == pytest.approx(1.0, rel=0.25)  # predict pads the ends
    assert old.reconstruct_signals_full(signals).unreliable is not None
