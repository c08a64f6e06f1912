"""A method's per-frame confidence in every report: the JSON report, the piecewise path, batch's
tables, the command line, the demo's plot and the viewer's data.

The confident method here is ridge with a made-up confidence (a fixed function of each frame's
signals, so that pieces and one piece agree), not the learned model's unfinished calibration.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from imuloco.app.confidence import MAX_BINS, MAX_SEGMENTS, Confidence, flagged_segments
from imuloco.app.pipeline import DEMO_CLIP, ModelChoice, reconstruct_file
from imuloco.cli import cli
from imuloco.io.sensorlog import write_generic_csv
from imuloco.measures.strides import with_confidence
from imuloco.methods.base import Reconstruction
from imuloco.sensors.simulate import simulate

GYRO_FLAG = 4.0  # rad/s: the made-up flag marks frames where the shank turns faster


def made_up_error(signals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A per-frame (error_m, unreliable) of the signals (T, 6): 3-5 cm with the gyro's norm."""
    g = np.linalg.norm(signals[:, 3:6], axis=1)
    return 0.03 + 0.02 * np.tanh(g / 5.0), g > GYRO_FLAG


@pytest.fixture
def confident(ridge_without_demo_clip, monkeypatch):
    """The fitted ridge, giving the made-up confidence for this test."""
    method = ridge_without_demo_clip

    def full(signals: np.ndarray) -> Reconstruction:
        err, flags = made_up_error(signals)
        return Reconstruction(method.reconstruct_signals(signals), err, flags, "made up")

    monkeypatch.setattr(method, "reconstruct_signals_full", full)
    return method


@pytest.fixture(scope="module")
def log_file(tmp_path_factory, sample_db):
    clip = next(c for c in sample_db.clips if c.name == DEMO_CLIP)
    rec = simulate(clip, ["right_ankle"], rate=100.0, noise="phone", seed=5)
    return write_generic_csv(rec, tmp_path_factory.mktemp("conf") / "walk.csv")


# ---- the summary -------------------------------------------------------------------------
def test_summary_merges_flagged_runs_and_leaves_nan_frames_out():
    fps = 30.0
    err = np.full(300, 0.02)
    err[:30] = 0.08
    err[100:110] = np.nan  # a gap: no prediction
    flags = np.zeros(300, bool)
    flags[30:40] = flags[45:50] = True  # 5 frames (0.17 s) apart: one segment
    flags[200:201] = True  # 2 s later: another
    j = Confidence(err, flags, fps, "n").to_json()
    finite = err[np.isfinite(err)]
    assert j["available"] and j["mean_error_m"] == pytest.approx(finite.mean(), abs=1e-4)
    assert j["p90_error_m"] == pytest.approx(np.percentile(finite, 90), abs=1e-4)
    assert j["max_error_m"] == 0.08
    assert j["unreliable_segments"] == [[1.0, round(50 / 30, 3)], [round(200 / 30, 3),
                                                                    round(201 / 30, 3)]]
    assert j["unreliable_segments_total"] == 2
    assert j["unreliable_fraction"] == pytest.approx(16 / 300, abs=1e-4)
    # per second: the first second is 8 cm, the fourth has its 20 finite frames only
    assert j["error_m_bin_s"] == 1 and len(j["error_m_per_second"]) == 10
    assert j["error_m_per_second"][0] == 0.08 and j["error_m_per_second"][3] == 0.02
    json.dumps(j, allow_nan=False)  # strict JSON: no NaN


def test_summary_is_none_where_the_method_gives_nothing():
    j = Confidence(None, None, 30.0, "ridge gives none").to_json()
    assert j["available"] is False and j["note"] == "ridge gives none"
    assert all(v is None for k, v in j.items() if k not in ("available", "note"))
    # a predicted error without flags
    j = Confidence(np.full(60, 0.05), None, 30.0).to_json()
    assert j["available"] and j["mean_error_m"] == 0.05
    assert j["unreliable_fraction"] is None and j["unreliable_segments"] is None
    # flags without an error
    flags = np.zeros(60, bool)
    flags[:15] = True
    j = Confidence(None, flags, 30.0).to_json()
    assert j["available"] and j["mean_error_m"] is None and j["error_m_per_second"] is None
    assert j["unreliable_fraction"] == 0.25 and j["unreliable_segments"] == [[0.0, 0.5]]


def test_a_long_recording_keeps_its_summary_small():
    fps, hours = 30.0, 3
    n = int(hours * 3600 * fps)
    flags = np.zeros(n, bool)
    starts = np.arange(0, n - 200, 1000)  # 324 flagged runs, 1000 frames apart
    lengths = 1 + np.arange(len(starts)) % 90
    for a, m in zip(starts, lengths):
        flags[a:a + m] = True
    err = np.where(flags, 0.1, 0.03)
    j = Confidence(err, flags, fps).to_json()
    assert j["unreliable_segments_total"] == len(starts)
    segs = j["unreliable_segments"]
    assert len(segs) == MAX_SEGMENTS and segs == sorted(segs)
    # the longest ones are kept
    durations = sorted(round((b - a) * fps) for a, b in segs)
    assert durations == sorted(lengths)[-MAX_SEGMENTS:] and durations[0] > 70
    assert j["error_m_bin_s"] == math.ceil(hours * 3600 / MAX_BINS) == 3
    assert len(j["error_m_per_second"]) == math.ceil(n / (3 * fps)) <= MAX_BINS


def test_flagged_segments_do_not_merge_runs_half_a_second_apart():
    flags = np.zeros(100, bool)
    flags[10:12] = flags[27:29] = True  # 15 frames apart at 30 fps: 0.5 s, not merged
    assert flagged_segments(flags, 30.0) == [(10, 12), (27, 29)]
    flags[26] = True  # 14 frames: merged
    assert flagged_segments(flags, 30.0) == [(10, 29)]


def test_stride_confidence_is_the_mean_predicted_error_over_the_stride():
    err = np.arange(100) / 1000.0
    rows = [{"foot": "left", "start_s": 1.0, "end_s": 2.0, "confidence": None},
            {"foot": "right", "start_s": 3.2, "end_s": 9.0, "confidence": None}]
    out = with_confidence(rows, err, 30.0)
    assert out[0]["confidence"] == pytest.approx(err[30:60].mean())
    assert out[1]["confidence"] == pytest.approx(err[96:100].mean())  # cut at the end
    assert with_confidence(rows, None, 30.0) is rows


# ---- the pipeline ------------------------------------------------------------------------
def test_report_carries_the_methods_confidence_and_height_scales_it(confident, log_file):
    from imuloco.measures.gait import height_scale
    from imuloco.sensors.reallog import read_log

    # the method's own confidence, as the fallback leaves it (it raises the predicted error
    # where it moves a part toward neutral: tests/test_fallback.py)
    motion, report = reconstruct_file(log_file, fitted=confident, fallback=False)
    c = report.confidence
    assert c.error_m.shape == (motion.num_frames,)
    # the method's own values, frame by frame (calibration only turns the phone's axes, so
    # the gyroscope's norm and with it the made-up error stay the same)
    from imuloco.methods.training import model_frames

    rec, _ = read_log(log_file)
    err, flags = made_up_error(model_frames(rec, confident.fps_))
    np.testing.assert_allclose(c.error_m, err, atol=1e-9)
    np.testing.assert_array_equal(c.unreliable, flags)
    j = report.to_json()["confidence"]
    assert j["available"] and j["mean_error_m"] == pytest.approx(err.mean(), abs=1e-4)
    assert 0 < j["unreliable_fraction"] < 1 and j["unreliable_segments"]
    assert j["note"] == "made up"
    strides = report.to_json()["strides"]
    assert strides and all(0.03 <= s["confidence"] <= 0.05 for s in strides)
    s = strides[0]
    a, b = round(s["start_s"] * motion.fps), round(s["end_s"] * motion.fps)
    assert s["confidence"] == pytest.approx(err[a:b].mean(), abs=1e-4)

    _, report2 = reconstruct_file(log_file, fitted=confident, height=1.95, fallback=False)
    k = height_scale(motion.skeleton, 1.95)
    assert k > 1.05
    np.testing.assert_allclose(report2.confidence.error_m, err * k, atol=1e-9)
    assert report2["confidence"]["p90_error_m"] == pytest.approx(j["p90_error_m"] * k,
                                                                 abs=2e-4)
    assert report2["confidence"]["unreliable_fraction"] == j["unreliable_fraction"]


def test_a_method_without_confidence_reports_none(ridge_without_demo_clip, log_file):
    _, report = reconstruct_file(log_file, fitted=ridge_without_demo_clip)
    j = report.to_json()
    assert j["confidence"]["available"] is False and j["confidence"]["mean_error_m"] is None
    assert "ridge" in j["confidence"]["note"]
    assert all(s["confidence"] is None for s in j["strides"])
    assert list(j)[-1] == "seconds"  # the keys before it keep their order


def test_cli_echoes_and_writes_the_confidence(confident, log_file, tmp_path, monkeypatch):
    from imuloco.app import pipeline

    monkeypatch.setattr(pipeline, "choose_model",
                        lambda *a, **k: ModelChoice(confident, "given", "made up"))
    out = tmp_path / "out"
    res = CliRunner().invoke(cli, ["reconstruct", str(log_file), "-o", str(out) + ".bvh",
                                   "--report", str(out) + ".json", "--html",
                                   str(out) + ".html"])
    assert res.exit_code == 0, res.output
    report = json.loads((tmp_path / "out.json").read_text())
    c = report["confidence"]
    assert f"predicted error {100 * c['mean_error_m']:.1f} cm" in res.output
    assert f"{100 * c['unreliable_fraction']:.1f} % of frames flagged unreliable" in res.output
    # the viewer holds the same per-frame values
    page = (tmp_path / "out.html").read_text()
    data = json.loads(page.split("const DATA = ", 1)[1].split(";\n", 1)[0])
    track = data["tracks"][0]
    assert len(track["error_mm"]) == data["frames"] == report["motion"]["frames"]
    per_s = np.array(track["error_mm"][:30]).mean() / 1000
    assert per_s == pytest.approx(c["error_m_per_second"][0], abs=2e-4)
    assert sum(track["unreliable"]) / data["frames"] == pytest.approx(
        c["unreliable_fraction"], abs=1e-3)


def test_cli_says_nothing_of_a_confidence_the_method_lacks(ridge_without_demo_clip, log_file,
                                                           tmp_path):
    model = ridge_without_demo_clip.save(tmp_path / "ridge.npz")
    res = CliRunner().invoke(cli, ["reconstruct", str(log_file), "--model", str(model), "-o",
                                   str(tmp_path / "o.bvh")])
    assert res.exit_code == 0, res.output
    assert "speed" in res.output and "predicted error" not in res.output


def test_the_shipped_learned_model_reports_its_own_predicted_error(log_file, tmp_path):
    """The seam end to end: ``learned`` gives an error per frame, whatever its calibration."""
    pytest.importorskip("torch")
    from imuloco.app.pipeline import choose_model

    choice = choose_model("learned", placement="right_ankle")
    if choice.source != "shipped":
        pytest.skip("no shipped learned model")
    motion, report = reconstruct_file(log_file, fitted=choice)
    c = report["confidence"]
    assert c["available"] and 0.001 < c["mean_error_m"] < 0.5  # metres, plausibly
    assert len(c["error_m_per_second"]) == math.ceil(motion.num_frames / motion.fps)
    assert all(s["confidence"] is not None for s in report["strides"])


def test_pieces_report_the_confidence_of_one_piece(confident, sample_db, tmp_path):
    from imuloco.app.chunked import reconstruct_to_bvh, reconstruction_pieces
    from imuloco.core.recording import Recording

    clip = sample_db.where(content="walk").clips[0]
    rec = simulate(clip, ["right_ankle"], 100.0, "phone", 1)
    span = rec.times[-1] - rec.times[0] + 0.01
    reps = int(np.ceil(30 / span))
    rec = Recording(np.concatenate([rec.times + k * span for k in range(reps)]),
                    np.tile(rec.acc, (reps, 1, 1)), np.tile(rec.gyro, (reps, 1, 1)),
                    rec.placements)
    whole = confident.reconstruct_full(rec)
    pieces = list(reconstruction_pieces(rec, confident, piece_s=10.0, warmup_s=3.0))
    assert len(pieces) == math.ceil(whole.motion.num_frames / 300) > 2
    assert [len(p.error_m) for p in pieces] == [p.motion.num_frames for p in pieces]
    np.testing.assert_allclose(np.concatenate([p.error_m for p in pieces]), whole.error_m)
    np.testing.assert_array_equal(np.concatenate([p.unreliable for p in pieces]),
                                  whole.unreliable)

    log = write_generic_csv(rec, tmp_path / "long.csv")
    report = reconstruct_to_bvh(log, tmp_path / "p.bvh", method=confident, piece_s=10.0,
                                calibrate=False)
    _, one = reconstruct_file(log, fitted=confident, calibrate=False)
    assert report["confidence"] == one["confidence"] and one["confidence"]["available"]
    # in the wearer's height, as the one-piece reconstruction scales it
    tall = reconstruct_to_bvh(log, tmp_path / "t.bvh", method=confident, piece_s=10.0,
                              calibrate=False, height=1.95)
    _, one = reconstruct_file(log, fitted=confident, calibrate=False, height=1.95)
    assert tall["confidence"] == one["confidence"]
    assert tall["confidence"]["mean_error_m"] > 1.05 * report["confidence"]["mean_error_m"]


def test_cli_pieces_echo_the_confidence(confident, log_file, tmp_path, monkeypatch):
    from imuloco.app import pipeline

    monkeypatch.setattr(pipeline, "choose_model",
                        lambda *a, **k: ModelChoice(confident, "given", "made up"))
    res = CliRunner().invoke(cli, ["reconstruct", str(log_file), "-o", str(tmp_path / "p.bvh"),
                                   "--piece-seconds", "10", "--report",
                                   str(tmp_path / "p.json")])
    assert res.exit_code == 0, res.output
    c = json.loads((tmp_path / "p.json").read_text())["confidence"]
    assert c["available"] and f"predicted error {100 * c['mean_error_m']:.1f} cm" in res.output


# ---- batch -------------------------------------------------------------------------------
def test_batch_fills_the_stride_tables_confidence(confident, log_file, tmp_path, monkeypatch):
    distributed = pytest.importorskip("distributed")
    import pyarrow.parquet as pq

    from imuloco.app import batch

    # the workers (threads of this process) load the job's model: here the confident one
    monkeypatch.setattr(batch, "worker_model", lambda sha, data: confident)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  **batch.LOCAL_CLUSTER) as cluster, \
            distributed.Client(cluster) as client:
        summary = batch.run_batch([log_file], tmp_path, fitted=confident, scheduler=client)
    assert summary["ok"] == 1
    report = json.loads((tmp_path / "walk.json").read_text())
    assert report["confidence"]["available"]
    strides = pq.read_table(tmp_path / "strides.parquet").to_pylist()
    assert len(strides) == len(report["strides"]) > 2
    assert [s["confidence"] for s in strides] == [s["confidence"] for s in report["strides"]]
    assert all(0.03 <= s["confidence"] <= 0.05 for s in strides)
    walker = pq.read_table(tmp_path / "walkers.parquet").to_pylist()[0]
    assert walker["mean_error_m"] == report["confidence"]["mean_error_m"]
    assert walker["unreliable_fraction"] == report["confidence"]["unreliable_fraction"] > 0


# ---- the demo's plot ---------------------------------------------------------------------
def test_error_plot_draws_predicted_beside_actual(sample_db, tmp_path, monkeypatch):
    from imuloco.measures.metrics import rmse_per_frame
    from imuloco.viz import plots

    gt, rec = sample_db.clips[0].slice(0, 60), sample_db.clips[0].slice(8, 68)  # 8 frames late
    pred = np.linspace(0.02, 0.06, 60)
    flags = np.zeros(60, bool)
    flags[20:30] = flags[50:52] = True
    figures = []
    save = plots._save
    monkeypatch.setattr(plots, "_save", lambda fig, *a: (figures.append(fig), save(fig, *a))[1])
    path = plots.plot_errors(gt, rec, tmp_path / "e.png", predicted_m=pred, unreliable=flags)
    assert path.stat().st_size > 1000
    ax = figures[0].axes[1]
    actual, predicted = ax.get_lines()
    np.testing.assert_allclose(actual.get_ydata(), rmse_per_frame(gt, rec))
    np.testing.assert_allclose(predicted.get_ydata(), pred * 100)
    spans = [p for p in ax.patches]
    assert len(spans) == 2
    assert "flagged unreliable" in [t.get_text() for t in ax.get_legend().get_texts()]


def test_demo_report_sets_predicted_beside_actual(sample_db):
    from imuloco.app.pipeline import confidence_check, confidence_markdown
    from imuloco.measures.metrics import rmse_per_frame

    gt, rec = sample_db.clips[0].slice(0, 60), sample_db.clips[0].slice(8, 68)  # 8 frames late
    actual = rmse_per_frame(gt, rec) / 100
    flags = actual > np.median(actual)
    c = Confidence(actual * 0.5, flags, gt.fps, "half the truth")
    check = confidence_check(gt, rec, c)
    assert check["ratio"] == pytest.approx(0.5, abs=1e-3)
    assert check["spearman"] == pytest.approx(1.0)
    assert check["p90_actual_error_m"] == pytest.approx(np.percentile(actual, 90), abs=1e-4)
    assert check["p90_predicted_error_m"] == pytest.approx(check["p90_actual_error_m"] / 2,
                                                           abs=1e-4)
    assert check["actual_error_unreliable_m"] > check["actual_error_reliable_m"]
    md = "\n".join(confidence_markdown({"confidence": c.to_json(),
                                        "confidence_check": check}))
    assert f"{100 * actual.mean():.2f} |" in md and "Predicted / actual: 0.5" in md
    none = confidence_check(gt, rec, Confidence(None, None, gt.fps))
    assert set(none.values()) == {None}


# ---- a BVH and its companion JSON in the viewer ------------------------------------------
def test_render_shows_a_reports_confidence(confident, log_file, tmp_path, monkeypatch):
    from imuloco.app import pipeline

    monkeypatch.setattr(pipeline, "choose_model",
                        lambda *a, **k: ModelChoice(confident, "given", "made up"))
    res = CliRunner().invoke(cli, ["reconstruct", str(log_file), "-o", str(tmp_path / "w.bvh"),
                                   "--report", str(tmp_path / "w.json")])
    assert res.exit_code == 0, res.output
    report = json.loads((tmp_path / "w.json").read_text())["confidence"]
    res = CliRunner().invoke(cli, ["render", str(tmp_path / "w.bvh"), "--report",
                                   str(tmp_path / "w.json"), "-o", str(tmp_path / "w.html")])
    assert res.exit_code == 0, res.output
    page = (tmp_path / "w.html").read_text()
    data = json.loads(page.split("const DATA = ", 1)[1].split(";\n", 1)[0])
    track, fps = data["tracks"][0], data["fps"]
    err = np.array(track["error_mm"]) / 1000
    # each second shows that second's mean
    for k, mean in enumerate(report["error_m_per_second"]):
        assert np.all(np.abs(err[int(k * fps):int((k + 1) * fps)] - mean) < 1e-4)
    flags = np.array(track["unreliable"], bool)
    expected = np.zeros(len(flags), bool)
    for a, b in report["unreliable_segments"]:
        expected[round(a * fps):round(b * fps)] = True
    assert flags.any() and np.array_equal(flags, expected)


@pytest.mark.parametrize(("text", "field"), [
    ("{", "not JSON"),
    ('{"gait": {}}', "field confidence:"),
    ('{"confidence": {"error_m_per_second": [0.1, "x"]}}', "confidence.error_m_per_second"),
    ('{"confidence": {"error_m_per_second": [0.1], "error_m_bin_s": 0}}',
     "confidence.error_m_bin_s"),
    ('{"confidence": {"unreliable_segments": [[2, 1]]}}', "confidence.unreliable_segments"),
    ('{"confidence": {"unreliable_segments": [[0, NaN]]}}', "confidence.unreliable_segments"),
])
def test_render_refuses_a_bad_report_naming_the_field(spinning_motion, tmp_path, text, field):
    from imuloco.io.bvh import write_bvh

    bvh = write_bvh(spinning_motion, tmp_path / "m.bvh")
    (tmp_path / "r.json").write_text(text)
    res = CliRunner().invoke(cli, ["render", str(bvh), "--report", str(tmp_path / "r.json"),
                                   "-o", str(tmp_path / "m.html")])
    assert res.exit_code == 1 and "r.json" in res.output and field in res.output, res.output
    assert "Traceback" not in res.output and not (tmp_path / "m.html").exists()


def test_a_report_with_extreme_numbers_still_gives_frames():
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "r.json"
        path.write_text(json.dumps({"confidence": {
            "error_m_per_second": [0.02, None], "error_m_bin_s": 1e-300,
            "unreliable_segments": [[1e300, 1e308], [0.0, 0.1]]}}))
        c = Confidence.from_report(path, 30, 30.0)
    assert np.isnan(c.error_m[1:]).all() and c.error_m[0] == 0.02
    assert c.unreliable.sum() == 3 and c.unreliable[:3].all()
