"""The benchmark runner, its report and the bench / evaluate / methods commands (sample only)."""

from __future__ import annotations

import json
from typing import Any, ClassVar

import numpy as np
import pytest
from click.testing import CliRunner

from imuloco.cli import cli
from imuloco.lab.bench import run_bench
from imuloco.lab.protocols import MOTION_TYPES, PROTOCOL_VERSION
from imuloco.methods import REGISTRY
from imuloco.methods.baselines import MeanPose

REQUIRED = ("method", "split", "noise", "placements", "motion_type", "mpjpe_cm", "rmse_cm",
            "upper_cm", "lower_cm", "angle_deg", "dpv", "jitter", "foot_skate_cm_s", "train_s",
            "offline_fps", "online_latency_ms_p50", "online_latency_ms_p99", "online_delay_ms",
            "model_bytes", "root_speed_err_cm_s", "path_err_cm", "protocol_version", "n_clips",
            "n_frames")
# measured costs: times vary between runs, and a model file records its training time and date
TIMINGS = ("train_s", "offline_fps", "online_latency_ms_p50", "online_latency_ms_p99",
           "model_bytes")
# 8 of the 16 sample clips, spread over all types: heldout-styles tests 4 of them
QUICK: dict[str, Any] = {"split_name": "heldout-styles", "noise": "phone",
                         "placements": ["right_ankle"], "data": None, "limit": 8, "seed": 0}


class OfflineMean(MeanPose):
    """The mean pose without an online mode, to check the null latencies."""

    name = "test-offline-mean"
    summary = "test only"
    supports_online: ClassVar[bool] = False

    def stream(self) -> Any:
        raise NotImplementedError


@pytest.fixture(scope="module")
def records(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    return run_bench(["mean", "ridge"], out=out, **QUICK), out


def test_records_have_the_promised_keys(records):
    recs, _ = records
    # --limit 8 spreads over the sample: its held-out-style clips cover every motion type
    assert [(r["method"], r["motion_type"]) for r in recs] == [
        (m, t) for m in ("mean", "ridge") for t in (*MOTION_TYPES[:4], "all")]
    for r in recs:
        assert set(REQUIRED) <= set(r)
        assert r["split"] == "heldout-styles" and r["noise"] == "phone"
        assert r["placements"] == ["right_ankle"]
        assert r["protocol_version"] == PROTOCOL_VERSION
        assert r["model_bytes"] > 0 and r["offline_fps"] > 0
        assert r["online_latency_ms_p99"] >= r["online_latency_ms_p50"] > 0
        assert r["online_delay_ms"] == 0  # neither looks ahead
    assert {r["n_clips"] for r in recs if r["motion_type"] == "all"} == {4}


def test_all_row_is_the_frame_weighted_mean(records):
    recs, _ = records
    for m in ("mean", "ridge"):
        rows = [r for r in recs if r["method"] == m and r["motion_type"] != "all"]
        total = next(r for r in recs if r["method"] == m and r["motion_type"] == "all")
        assert total["n_frames"] == sum(r["n_frames"] for r in rows)
        for key in ("mpjpe_cm", "dpv", "path_err_cm"):
            w = np.average([r[key] for r in rows], weights=[r["n_frames"] for r in rows])
            assert total[key] == pytest.approx(w, rel=1e-12)


def test_ridge_beats_the_mean_pose(records):
    recs, _ = records
    total = {r["method"]: r for r in recs if r["motion_type"] == "all"}
    assert total["ridge"]["mpjpe_cm"] < total["mean"]["mpjpe_cm"]
    # one pose at a constant speed and yaw rate: a circle, whose jerk v w^2 is tiny
    assert total["mean"]["jitter"] < 1.0 < total["ridge"]["jitter"]


def test_files_written(records):
    recs, out = records
    assert json.loads((out / "results.json").read_text()) == json.loads(json.dumps(recs))
    per_clip = json.loads((out / "per_clip.json").read_text())
    assert len(per_clip) == 2 * 4
    md = (out / "results.md").read_text()
    assert "| mean |" in md and "| ridge |" in md and "walk-turn-left" in md
    pytest.importorskip("matplotlib")
    assert (out / "error_per_joint.png").stat().st_size > 1000
    assert (out / "error_over_time.png").stat().st_size > 1000


def test_same_command_twice_gives_the_same_numbers(records):
    again = run_bench(["mean", "ridge"], out=None, **QUICK)
    first, _ = records
    strip = [{k: v for k, v in r.items() if k not in TIMINGS} for r in first]
    assert strip == [{k: v for k, v in r.items() if k not in TIMINGS} for r in again]
    for r, s in zip(first, again):  # the header's time stamp may compress a few bytes apart
        assert abs(r["model_bytes"] - s["model_bytes"]) < 64


def test_offline_method_has_null_latency(monkeypatch):
    monkeypatch.setitem(REGISTRY, OfflineMean.name, OfflineMean)
    recs = run_bench([OfflineMean.name], out=None, **QUICK)
    assert all(r["online_latency_ms_p50"] is None and r["online_latency_ms_p99"] is None
               and r["online_delay_ms"] is None for r in recs)


def test_unknown_method_fails_before_work():
    with pytest.raises(KeyError, match="available"):
        run_bench(["no-such-method"], out=None, **QUICK)


def test_cli_methods_and_bench(tmp_path):
    runner = CliRunner()
    res = runner.invoke(cli, ["methods"])
    assert res.exit_code == 0
    for name in ("mean", "ridge", "knn"):
        assert any(line.startswith(name + " ") for line in res.output.splitlines())
    res = runner.invoke(cli, ["bench", "--method", "mean", "--split", "heldout-styles",
                              "--limit", "8", "--out", str(tmp_path / "b")])
    assert res.exit_code == 0, res.output
    recs = json.loads((tmp_path / "b" / "results.json").read_text())
    assert recs[-1]["method"] == "mean" and recs[-1]["motion_type"] == "all"
    res = runner.invoke(cli, ["bench", "--method", "nope", "--out", str(tmp_path / "c")])
    assert res.exit_code != 0 and "unknown method" in res.output


def test_cli_evaluate(tmp_path, sample_db):
    from imuloco.io.bvh import write_bvh

    a, b = sample_db.clips[0], sample_db.clips[3]  # two run clips, same skeleton
    write_bvh(a, tmp_path / "a.bvh")
    write_bvh(b, tmp_path / "b.bvh")
    res = CliRunner().invoke(cli, ["evaluate", str(tmp_path / "a.bvh"), str(tmp_path / "a.bvh"),
                                   "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.output)["mpjpe_cm"] == pytest.approx(0.0, abs=1e-6)
    res = CliRunner().invoke(cli, ["evaluate", str(tmp_path / "a.bvh"), str(tmp_path / "b.bvh")])
    assert res.exit_code == 0, res.output
    assert "mpjpe_cm" in res.output


def test_cli_evaluate_rejects_other_skeletons(tmp_path, sample_db, spinning_motion):
    from imuloco.io.bvh import write_bvh

    write_bvh(sample_db.clips[0], tmp_path / "a.bvh")
    write_bvh(spinning_motion, tmp_path / "s.bvh")
    res = CliRunner().invoke(cli, ["evaluate", str(tmp_path / "a.bvh"), str(tmp_path / "s.bvh")])
    assert res.exit_code != 0 and "skeleton" in res.output


def test_method_spec_carries_hyperparameters():
    from imuloco.methods.registry import parse_method_spec

    assert parse_method_spec("ridge") == ("ridge", {})
    assert parse_method_spec("eom2014[variant=mlp-no-hmm;context=7]") == (
        "eom2014", {"variant": "mlp-no-hmm", "context": 7})
    with pytest.raises(KeyError, match="expected"):
        parse_method_spec("ridge[window")
    # Python's spellings of true, false and none are read as such, and a value of the wrong
    # kind is refused by name before any work ("True" reached torch's GRU as a string)
    assert parse_method_spec("learned[bidirectional=True;mirror=False]")[1] == {
        "bidirectional": True, "mirror": False}
    from imuloco.errors import InputError
    from imuloco.methods import get_method

    for spec, word in (("learned[bidirectional=yes]", "true or false"),
                       ("learned[epochs=2.5]", "whole number"), ("ridge[alpha=big]", "number"),
                       ("ridge[nosuch=1]", "no parameter"),
                       # a default of None or a string: the annotation's kind, the string
                       ("learned[threads=two]", "whole number or None"),
                       ("tautges2008[style_rank=x]", "whole number or None"),
                       ("mousas2017[engine=3]", "a string"),
                       # a constructor's own check of a choice, named as the others
                       ("eom2014[variant=foo]", "unknown variant 'foo'"),
                       ("mousas2017[engine=fast]", "engine must be one of")):
        name, params = parse_method_spec(spec)
        with pytest.raises(InputError, match=word):
            get_method(name, **params)
    assert get_method("learned", threads=None).threads is None
    assert get_method("tautges2008", style_rank=2).style_rank == 2
    recs = run_bench(["ridge[window=3]"], out=None, **QUICK)
    assert {r["method"] for r in recs} == {"ridge[window=3]"}
    # the hyperparameter reached the method: a 3-sample window differs from the default
    default = run_bench(["ridge"], out=None, **QUICK)
    assert recs[-1]["mpjpe_cm"] != default[-1]["mpjpe_cm"]


def test_a_split_that_leaves_no_test_clips_is_refused_by_name(sample_db):
    """Data with none of the held-out styles (e.g. ``--limit`` too small) is an InputError
    naming the split and the counts, which the CLI prints as one line, not a traceback."""
    from imuloco.errors import InputError
    from imuloco.lab.protocols import HELDOUT_STYLES, split

    keep = [i for i, lab in enumerate(sample_db.labels) if lab.get("style") not in HELDOUT_STYLES]
    with pytest.raises(InputError, match=r"heldout-styles.*\(\d+ / 0 clips\)"):
        split(sample_db.subset(keep), "heldout-styles")


def test_path_and_animation_keys_in_every_record(records):
    recs, out = records
    for r in recs:
        for key in ("path_distance_ratio", "path_distance_mae_pct", "path_stride_mae_pct",
                    "path_stride_mae_m", "path_end_point_error_pct", "path_raw_distance_ratio",
                    "path_raw_distance_mae_pct", "animation_mpjpe_cm",
                    "animation_foot_skate_cm_s"):
            assert key in r
        assert r["path_distance_ratio"] is not None and r["animation_mpjpe_cm"] > 0
    md = (out / "results.md").read_text()
    assert "raw root" in md


def test_bench_path_figures_are_those_of_reconstructs_animation(sample_db, tmp_path):
    """One code path: the bench scores the path of the animation ``reconstruct`` writes
    (the method's output following the shin's path estimator), on the same recording."""
    from imuloco.app.pipeline import reconstruct_file
    from imuloco.io.sensorlog import write_generic_csv
    from imuloco.lab.bench import PATH_CLIP_KEYS, measure
    from imuloco.methods import get_method
    from imuloco.methods.training import Example, to_frames
    from imuloco.paths.metrics import motion_path_errors
    from imuloco.sensors.multi import read_sensors
    from imuloco.sensors.simulate import simulate

    k = [lab["name"] for lab in sample_db.labels].index("dataset-2_walk_normal_001")
    clip, labels = sample_db.clips[k], sample_db.labels[k]
    train = sample_db.subset([i for i in range(len(sample_db)) if i != k])
    method = get_method("ridge").fit(train, ["right_ankle"], "phone", 0)
    csv = tmp_path / "walk.csv"
    write_generic_csv(simulate(clip, ["right_ankle"], 100.0, "phone", 11), csv)
    rec, _ = read_sensors(csv, placement="right_ankle")  # as reconstruct imports it
    bench = measure(method, [Example(clip, to_frames(rec, clip), labels, rec)])["clips"][0]
    motion, report = reconstruct_file(csv, fitted=method)
    assert report.to_json()["path"]["source"] == "shank-pivot"  # it followed a path
    want = motion_path_errors(motion, clip)
    for key in PATH_CLIP_KEYS:
        assert bench[f"path_{key}"] == pytest.approx(want[key], rel=1e-9, abs=1e-12), key
    # and the raw root's figures are another thing: the follower moved the root
    assert bench["path_raw_distance_ratio"] != pytest.approx(bench["path_distance_ratio"],
                                                             rel=1e-3)


def test_two_sensors_bench_rows_have_the_body_parts(tmp_path):
    """``bench run --placement right_ankle,left_ankle`` (issue 46): every method reads both
    shins (mousas2017's HMM both as one observation), each row has legs, arms and trunk, and
    results.md sets them against the mean pose."""
    recs = run_bench(["mean", "ridge", "mousas2017"], out=tmp_path,
                     **{**QUICK, "placements": ["right_ankle", "left_ankle"]})
    rows = {r["method"]: r for r in recs if r["motion_type"] == "all"}
    for r in rows.values():
        assert r["placements"] == ["right_ankle", "left_ankle"]
        assert all(r[f"{g}_cm"] > 0 for g in ("legs", "arms", "trunk"))
    for m in ("ridge", "mousas2017"):
        assert rows[m]["legs_cm"] < 0.8 * rows["mean"]["legs_cm"], (m, rows[m]["legs_cm"])
    assert "| mousas2017 | all |" in (tmp_path / "results.md").read_text()
