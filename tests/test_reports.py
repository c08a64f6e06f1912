"""Typed results of the application layer: the model choice with its source and the
reconstruction report, whose JSON keys are a contract."""

from __future__ import annotations

import json

import pytest

from imuloco.app import pipeline
from imuloco.io.sensorlog import write_generic_csv
from imuloco.sensors.simulate import simulate

# the report's keys as `imuloco reconstruct --report` and batch's NAME.json have written them
REPORT_KEYS = ["recording", "calibration", "feet_pinned_by", "method", "model", "placement",
               "motion", "height_m", "gait", "gait_source", "gait_note", "strides",
               "signal_cadence_spm", "signal_swing_deg", "plausibility", "confidence",
               "seconds"]
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
    from imuloco.sensors.calibration import MOUNTINGS
    from imuloco.sensors.placement import PRESETS

    for name, p in PRESETS.items():
        assert p.mounting is None or p.mounting in MOUNTINGS, name
        assert p.gait is None or p.gait in ESTIMATORS, name
        assert bool(p.needs) == (p.extra is not None), name
        assert p.model is None or pipeline.shipped_model("learned", name) is not None, name
        assert p.path_estimator is None  # none yet: imuloco.paths plugs in here
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
    import imuloco.phases
    import imuloco.phases.contacts
    import imuloco.phases.gait

    calls = []
    real = imuloco.phases.contacts.foot_contacts

    def counted(*a, **k):
        calls.append(1)
        return real(*a, **k)

    for module in (imuloco.phases, imuloco.phases.contacts, imuloco.phases.gait):
        monkeypatch.setattr(module, "foot_contacts", counted)
    _, report = pipeline.reconstruct_file(log_file, fitted=ridge_without_demo_clip)
    assert report.feet_pinned_by == "pipeline" and len(calls) == 2


def test_write_outputs_writes_the_set_and_refuses_to_overwrite(tmp_path, log_file,
                                                              ridge_without_demo_clip):
    from imuloco.app.outputs import Outputs, write_outputs
    from imuloco.errors import ImulocoError, OutputExistsError
    from imuloco.io.bvh import read_bvh

    motion, report = pipeline.reconstruct_file(log_file, fitted=ridge_without_demo_clip)
    outputs = Outputs(tmp_path / "walk.bvh", tmp_path / "walk.json", unit="m")
    outputs.check()
    assert write_outputs(outputs, report, motion) == [outputs.bvh, outputs.report]
    assert json.loads(outputs.report.read_text()) == json.loads(json.dumps(report.to_json()))
    assert read_bvh(outputs.bvh).num_frames == motion.num_frames
    with pytest.raises(OutputExistsError, match="--force"):
        outputs.check()
    outputs.check(force=True)
    with pytest.raises(ImulocoError, match="overwrite an input"):
        Outputs(tmp_path / "out.bvh", log_file).check(force=True, inputs=[log_file])
