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
               "signal_cadence_spm", "signal_swing_deg", "plausibility", "path", "confidence",
               "seconds"]
PATH_KEYS = ["source", "note", "distance_m", "strides", "stride_length_m", "animation",
             "stride_agreement_pct"]
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
    assert report["gait"] is report.gait  # the JSON view, for code written against the dict
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
