"""Batch reconstruction of many walkers: outputs, summary, parallel = serial, bad files."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from click.testing import CliRunner

from imuloco.app.batch import find_recordings, output_names, run_batch
from imuloco.cli import cli
from imuloco.evaluate.gait import gait_parameters
from imuloco.io.bvh import read_bvh
from imuloco.io.sensorlog import write_generic_csv
from imuloco.sensors.simulate import simulate

WALKERS = ("dataset-2_walk_normal_001", "dataset-2_walk_active_001",
           "dataset-2_walk-turn-left_normal_001")


@pytest.fixture(scope="module")
def fitted(sample_db):
    """ridge fitted on the sample without the walkers' clips."""
    from imuloco.methods import get_method

    keep = [i for i, lab in enumerate(sample_db.labels) if lab["name"] not in WALKERS]
    return get_method("ridge").fit(sample_db.subset(keep), ["right_ankle"], "phone", 0)


@pytest.fixture(scope="module")
def logs(tmp_path_factory, sample_db):
    """Three simulated walkers (two logs share a file name in different folders) and a
    broken log."""
    root = tmp_path_factory.mktemp("walkers")
    paths = []
    for k, name in enumerate(WALKERS):
        clip = next(c for c in sample_db.clips if c.name == name)
        folder = root / f"walker{k}"
        folder.mkdir()
        stem = "phone" if k < 2 else name
        rec = simulate(clip, ["right_ankle"], 100.0, "phone", seed=20 + k)
        paths.append(write_generic_csv(rec, folder / f"{stem}.csv"))
    bad = root / "broken.csv"
    bad.write_text("time_s,acc_x,acc_y\n0,1,2\n")
    return paths, bad


def test_names_are_distinct_and_globs_expand(logs, tmp_path):
    paths, _ = logs
    assert output_names(paths) == ["walker0_phone", "walker1_phone", WALKERS[2]]
    root = paths[0].parent.parent
    found = find_recordings([paths[0]], [str(root / "**" / "*.csv")])
    assert found[0] == paths[0] and len(found) == 4  # paths[0] once, then the other three


def test_batch_writes_one_bvh_and_report_per_walker_and_a_summary(logs, fitted, tmp_path,
                                                                  sample_db):
    paths, bad = logs
    summary = run_batch([*paths, bad], tmp_path, jobs=1, fitted=fitted)
    assert summary["ok"] == 3 and summary["failed"] == 1
    rows = summary["recordings"]
    assert [r["name"] for r in rows] == [*output_names(paths), "broken"]
    assert rows[-1]["status"] == "error" and "broken.csv" in rows[-1]["error"]
    for row, name in zip(rows[:3], WALKERS):
        clip = next(c for c in sample_db.clips if c.name == name)
        motion = read_bvh(tmp_path / f"{row['name']}.bvh")
        assert motion.num_frames == row["frames"]
        assert abs(motion.duration - clip.duration) < 0.2
        report = json.loads((tmp_path / f"{row['name']}.json").read_text())
        assert report["gait"]["cadence_spm"] == row["cadence_spm"]
        # the legs' rhythm is the walker's cadence (too short a clip has none), and the speed
        # the walker's to within a third (ground truth: strikes of the clean capture)
        truth = gait_parameters(clip)
        if row["cadence_rhythm_spm"] is not None:
            assert row["cadence_rhythm_spm"] == pytest.approx(truth["cadence_spm"], rel=0.15)
        assert row["speed_mps"] == pytest.approx(truth["speed_mps"], rel=0.3)
    with open(tmp_path / "summary.csv") as f:
        table = list(csv.DictReader(f))
    assert [t["name"] for t in table] == [r["name"] for r in rows]
    assert float(table[0]["cadence_rhythm_spm"]) == pytest.approx(rows[0]["cadence_rhythm_spm"])
    assert json.loads((tmp_path / "summary.json").read_text())["frames"] == summary["frames"]
    with pytest.raises(FileExistsError):  # never overwrites unless asked
        run_batch(paths, tmp_path, fitted=fitted)


def test_parallel_batch_gives_the_serial_results(logs, fitted, tmp_path):
    pytest.importorskip("joblib")
    paths, _ = logs
    serial = run_batch(paths, tmp_path / "serial", jobs=1, fitted=fitted)
    parallel = run_batch(paths, tmp_path / "parallel", jobs=2, fitted=fitted)
    for a, b in zip(serial["recordings"], parallel["recordings"]):
        assert {k: v for k, v in a.items() if k != "seconds"} == \
               {k: v for k, v in b.items() if k != "seconds"}
        m1 = read_bvh(tmp_path / "serial" / f"{a['name']}.bvh")
        m2 = read_bvh(tmp_path / "parallel" / f"{b['name']}.bvh")
        np.testing.assert_allclose(m1.positions(), m2.positions())


def test_cli_batch(logs, fitted, tmp_path):
    paths, bad = logs
    model = fitted.save(tmp_path / "ridge.npz")
    out = tmp_path / "out"
    res = CliRunner().invoke(cli, ["batch", str(paths[2]), "--glob",
                                   str(paths[0].parent / "*.csv"), "--out", str(out),
                                   "--model", str(model)])
    assert res.exit_code == 0, res.output
    assert "2 of 2 reconstructed" in res.output and "recordings/min" in res.output
    assert (out / f"{WALKERS[2]}.bvh").exists() and (out / "phone.bvh").exists()
    res = CliRunner().invoke(cli, ["batch", str(bad), "--out", str(tmp_path / "bad"),
                                   "--model", str(model)])
    assert res.exit_code == 1 and "1 recording(s) failed" in res.output
    res = CliRunner().invoke(cli, ["batch", "--out", str(out)])
    assert res.exit_code == 2 and "no recordings" in res.output
