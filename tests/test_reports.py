"""Typed results of the application layer: the model choice with its source and the
reconstruction report, whose JSON keys are a contract."""

from __future__ import annotations

import json

import numpy as np
import pytest

from imuloco.app import pipeline
from imuloco.io.sensorlog import write_generic_csv
from imuloco.sensors.simulate import simulate

# the report's keys as `imuloco reconstruct --report` and batch's NAME.json have written them
REPORT_KEYS = ["recording", "calibration", "feet_pinned_by", "method", "model", "placement",
               "sensors", "motion", "height_m", "gait", "gait_source", "gait_note", "strides",
               "signal_cadence_spm", "signal_swing_deg", "plausibility", "path", "confidence",
               "seconds"]
PATH_KEYS = ["source", "note", "distance_m", "strides", "stride_length_m", "animation",
             "stride_agreement_pct", "track_xy", "footfalls"]
RECORDING_KEYS = ["files", "format", "duration_s", "source_rate_hz", "samples", "unsorted",
                  "duplicates", "acc_unit", "gyro_unit", "gaps", "time_unit", "platform"]


@pytest.fixture(scope="module")
def log_file(tmp_path_factory, sample_db):
    clip = next(c for c in sample_db.clips if c.name == pipeline.DEMO_CLIP)
    rec = simulate(clip.slice(0, 150), ["right_ankle"], 100.0, "phone", seed=5)
    return write_generic_csv(rec, tmp_path_factory.mktemp("log") / "walk.csv")


def test_report_to_json_keeps_the_contract_keys(log_file, ridge_without_demo_clip):
    _, report = pipeline.reconstruct_file(log_file, fitted=ridge_without_demo_clip)
    data = json.loads(json.dumps(report.to_json()))
    assert list(data) == REPORT_KEYS
    assert list(data["path"]) == PATH_KEYS  # issue 40: the path that drove the root
    assert list(data["recording"]) == RECORDING_KEYS
    assert list(data["motion"]) == ["frames", "fps", "duration_s"]
    assert data["method"] == report.method == "ridge"
    assert data["model"] == "given fitted method 'ridge'" and report.model.source == "given"
    assert report["gait"] == report.gait.to_json()  # the JSON view, for code written against
    assert list(data["gait"]) == list(report.gait.to_dict())  # the dict (and its order)
    _, uncalibrated = pipeline.reconstruct_file(log_file, fitted=ridge_without_demo_clip,
                                                calibrate=False)
    assert "calibration" not in uncalibrated.to_json()


def test_model_choice_says_where_the_model_came_from(monkeypatch, tmp_path,
                                                     ridge_without_demo_clip):
    path = ridge_without_demo_clip.save(tmp_path / "r.npz")
    choice = pipeline.choose_model(model=path)
    assert choice.source == "file" and choice.path == path and choice.method.name == "ridge"
    assert str(choice) == f"model file {path} (method 'ridge')"
    monkeypatch.setattr(pipeline, "shipped_model",
                        lambda method, placement: path if method == "ridge" else None)
    choice = pipeline.choose_model("ridge")
    assert choice.source == "shipped" and choice.path == path
    monkeypatch.setattr(pipeline, "shipped_model", lambda method, placement: None)
    choice = pipeline.choose_model("mean")
    assert choice.source == "fitted" and choice.path is None and "on the fly" in str(choice)
    with pytest.raises(ValueError, match="trained for"):
        pipeline.choose_model(model=path, placement="left_ankle")


# ---- the placement registry ---------------------------------------------------------------
def test_every_placement_declaration_names_what_exists():
    """Each preset's mounting, gait estimator, extra and shipped model resolve; the tables
    that read the registry agree with it."""
    from imuloco.measures.sensorgait import ESTIMATORS
    from imuloco.paths.registry import BY_NAME
    from imuloco.sensors.calibration import MOUNTINGS
    from imuloco.sensors.placement import PRESETS

    for name, p in PRESETS.items():
        assert p.mounting is None or p.mounting in MOUNTINGS, name
        assert p.gait is None or p.gait in ESTIMATORS, name
        assert bool(p.needs) == (p.extra is not None), name
        assert p.model is None or pipeline.shipped_model("learned", name) is not None, name
        assert p.path_estimator is None or p.path_estimator in BY_NAME, name
    assert pipeline.GAIT_EXTRA == {"right_foot": "gaitmap", "left_foot": "gaitmap",
                                   "lower_back": "mobgap"}
    assert {n for n, p in PRESETS.items() if p.gait} == set(pipeline.GAIT_EXTRA)
    assert pipeline.shipped_model("learned", "right_thigh") is None


def test_a_placement_is_one_declaration(monkeypatch, sample_db):
    """A new preset, declared once, is simulated, calibrated by its routine and measured by the
    motion's gait (no sensor estimator), with no other edit."""
    from dataclasses import replace

    from imuloco.measures.sensorgait import estimator_of
    from imuloco.sensors.calibration import calibrate
    from imuloco.sensors.placement import PRESETS

    shin = replace(PRESETS["right_ankle"], name="right_shin", fraction=0.5, model=None)
    monkeypatch.setitem(PRESETS, "right_shin", shin)
    rec = simulate(sample_db.where(content="walk").clips[0], ["right_shin"], 100.0, "phone", 1)
    _, (mount,) = calibrate(rec)
    assert mount.up_source in ("still", "walk") and mount.swings >= 2
    assert estimator_of("right_shin") is None and pipeline.shipped_model("learned",
                                                                          "right_shin") is None


def test_the_reported_motions_contacts_are_found_once(monkeypatch, log_file,
                                                      ridge_without_demo_clip):
    """One reconstruction searches its feet's contacts twice: once to pin them, once on the
    reported motion for the gait, the strides and the plausibility checks (it was three
    times)."""
    import imuloco.methods.postprocess
    import imuloco.phases
    import imuloco.phases.contacts
    import imuloco.phases.gait

    calls = []
    real = imuloco.phases.contacts.foot_contacts

    def counted(*a, **k):
        calls.append(1)
        return real(*a, **k)

    for module in (imuloco.phases, imuloco.phases.contacts, imuloco.phases.gait,
                   imuloco.methods.postprocess):  # each module that binds the name
        monkeypatch.setattr(module, "foot_contacts", counted)
    _, report = pipeline.reconstruct_file(log_file, fitted=ridge_without_demo_clip)
    assert report.feet_pinned_by == "pipeline" and len(calls) == 2


def test_write_outputs_writes_the_set_and_refuses_to_overwrite(tmp_path, log_file,
                                                              ridge_without_demo_clip):
    from imuloco.app.outputs import Outputs, write_outputs
    from imuloco.errors import ImulocoError, OutputExistsError
    from imuloco.io.atomic import sha256_file
    from imuloco.io.bvh import read_bvh

    motion, report = pipeline.reconstruct_file(log_file, fitted=ridge_without_demo_clip)
    outputs = Outputs(tmp_path / "walk.bvh", tmp_path / "walk.json", unit="m")
    outputs.check()
    assert write_outputs(outputs, report, motion) == [outputs.bvh, outputs.report]
    written = json.loads(outputs.report.read_text())
    assert written.pop("outputs") == {"bvh": outputs.bvh.name,
                                      "bvh_sha256": sha256_file(outputs.bvh)}
    assert written == json.loads(json.dumps(report.to_json()))
    assert read_bvh(outputs.bvh).num_frames == motion.num_frames
    with pytest.raises(OutputExistsError, match="--force"):
        outputs.check()
    outputs.check(force=True)
    with pytest.raises(ImulocoError, match="overwrite an input"):
        Outputs(tmp_path / "out.bvh", log_file).check(force=True, inputs=[log_file])


# ---- the readable summary beside a report (reconstruct --report NAME.json -> NAME.md) ------
def _summary_report(confidence: bool) -> dict:
    strides = [{"foot": foot, "start_s": t + (0.55 if foot == "left" else 0.0),
                "duration_s": 1.1, "length_m": 1.3 + 0.01 * k, "speed_mps": 1.2,
                "stance_s": 0.66, "swing_s": 0.44, "confidence": 0.03}
               for k, t in enumerate(np.arange(0, 30, 1.1)) for foot in ("left", "right")]
    report = {"recording": {"files": ["walk.csv"], "format": "generic", "duration_s": 30.0,
                            "source_rate_hz": 100.0, "gaps": [[2.0, 2.5], [20.0, 21.0]]},
              "placement": "right_ankle", "model": "a test model", "height_m": None,
              "motion": {"frames": 900, "fps": 30.0, "duration_s": 30.0},
              "gait": {"steps": 54.0, "cadence_spm": 109.1, "cadence_rhythm_spm": 109.0,
                       "stride_length_m": 1.4, "speed_mps": 1.27},
              "gait_source": "the reconstructed motion", "gait_note": "model-derived: test",
              "strides": strides, "signal_cadence_spm": 108.8, "signal_swing_deg": 74.0,
              "plausibility": {"left_shank_swing_deg": 70.0, "right_shank_swing_deg": 72.0},
              "confidence": {"available": False, "note": "no confidence here"}}
    if confidence:
        report["confidence"] = {
            "available": True, "mean_error_m": 0.179, "p90_error_m": 0.22, "max_error_m": 0.39,
            "unreliable_fraction": 0.027, "unreliable_segments": [[3.0, 4.5]],
            "unreliable_segments_total": 1, "error_m_bin_s": 1,
            "error_m_per_second": [0.15 + 0.001 * k for k in range(30)], "note": "calibrated"}
    return report


def test_summary_draws_the_plots_a_user_reads_and_explains_the_predicted_error(tmp_path):
    pytest.importorskip("matplotlib")
    from imuloco.app.summary import write_summary

    written = write_summary(_summary_report(True), tmp_path / "walk.md")
    assert [p.name for p in written] == ["walk.md", "walk-strides.png", "walk-symmetry.png",
                                         "walk-contacts.png", "walk-error.png"]
    md = (tmp_path / "walk.md").read_text()
    assert "mean 17.90 cm, 90th percentile 22.00 cm" in md
    assert "2.7 % in 1 stretch(es)" in md
    assert "Here 1 of the 1 flagged stretches listed start within 2 s of a gap" in md
    assert "Why it can be high with few frames flagged" in md and "10 cm" in md
    assert "| steps | 54 |" in md and "| cadence (steps/min) | 109 |" in md
    assert "Gait note: model-derived: test" in md
    assert "docs/results/real/shin-stride/README.md" in md  # the shin caveat's evidence
    assert "--height METRES" in md  # lengths on the model's skeleton
    # nothing is replaced without overwrite
    from imuloco.errors import ImulocoError

    with pytest.raises(ImulocoError, match="walk"):
        write_summary(_summary_report(True), tmp_path / "walk.md")


def test_summary_error_plot_draws_the_seconds_and_flagged_stretches(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    from imuloco.viz import gaitplots

    saved = {}
    real_save = gaitplots._save
    monkeypatch.setattr(gaitplots, "_save", lambda fig, path, overwrite: (
        saved.setdefault("fig", fig), real_save(fig, path, overwrite))[1])
    gaitplots.plot_predicted_error([0.1, None, 0.3], 2.0, tmp_path / "e.png", [[1.0, 2.0]])
    fig = saved["fig"]
    ax = fig.axes[0]
    line = ax.get_lines()[0]
    np.testing.assert_allclose(line.get_xdata(), [1.0, 3.0, 5.0])  # bin centres
    np.testing.assert_allclose(line.get_ydata(), [10.0, np.nan, 30.0])  # cm
    assert "flagged unreliable" in [t.get_text() for t in ax.get_legend().get_texts()]


def test_model_gait_note_checks_the_legs_against_the_shanks_own_swing():
    from imuloco.measures.sensorgait import model_gait_note

    gait = {"cadence_rhythm_spm": 101.0}
    short = model_gait_note("right_ankle", gait, 100.8, 79.0, {"left": 44.0, "right": 66.0})
    assert short.startswith("model-derived") and "0.2 % apart" in short
    assert "likely read short" in short and "shin-stride" in short
    even = model_gait_note("right_ankle", gait, 100.8, 74.0, {"left": 73.0, "right": 74.0})
    assert "swing as the sensor says" in even
    off = model_gait_note("right_thigh", {"cadence_rhythm_spm": 141.0}, 109.0)
    assert "differs from the sensor's own rhythm" in off
    steps = model_gait_note("right_thigh", {"cadence_rhythm_spm": 108.9, "cadence_spm": 141.2},
                            108.6)
    assert "agrees with" in steps and "141.2 steps/min, 30 % off the legs' rhythm" in steps
    assert "nothing model-free checks them" in off


def test_summary_of_a_shoe_sensor_says_its_gait_is_measured(tmp_path):
    from imuloco.app.summary import summary_markdown

    report = _summary_report(False) | {
        "placement": "right_foot", "gait_note": None, "signal_swing_deg": None,
        "gait_source": "the right_foot sensor's signal: gaitmap RtsKalman ZUPT trajectory"}
    md = summary_markdown(report, "foot")
    assert "A shoe sensor measures gait itself" in md and "shin" not in md
    assert "Gait note: measured by the sensor itself" in md
    assert "--height METRES" not in md  # its strides are in real metres
    assert "gives no per-frame confidence" not in md and "no confidence here" in md
