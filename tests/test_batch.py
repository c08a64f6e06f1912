"""Batch reconstruction of many walkers on a real (in-process) Dask cluster: outputs, tables,
resume, --force, bad files, atomic writes."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner

from imuloco.app.batch import (
    LOCAL_CLUSTER,
    WALKER_FIELDS,
    find_recordings,
    output_names,
    run_batch,
)
from imuloco.cli import cli
from imuloco.errors import OutputExistsError
from imuloco.io.bvh import read_bvh
from imuloco.io.sensorlog import write_generic_csv
from imuloco.measures.gait import gait_parameters
from imuloco.measures.strides import STRIDE_FIELDS, stride_rows
from imuloco.sensors.simulate import simulate

distributed = pytest.importorskip("distributed")

WALKERS = ("dataset-2_walk_normal_001", "dataset-2_walk_active_001",
           "dataset-2_walk-turn-left_normal_001")


@pytest.fixture(scope="module")
def client():
    """Two worker threads of a real Dask cluster in this process."""
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  **LOCAL_CLUSTER) as cluster, \
            distributed.Client(cluster) as c:
        yield c


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


def test_a_realworld_pair_is_one_walker(tmp_path):
    """``--glob '*.csv'`` on RealWorld logs matches both files of each pair: the acc_ file
    reads the pair, its gyroscope file is not a walker of its own (it was a failed row)."""
    for name in ("acc_a.csv", "gyroscope_a.csv", "Gyroscope_b.csv", "other.csv"):
        (tmp_path / name).write_text("")
    found = find_recordings([], [str(tmp_path / "*.csv")])
    assert [p.name for p in found] == ["Gyroscope_b.csv", "acc_a.csv", "other.csv"]


def test_a_sensor_logger_folder_is_one_walker(fitted, client, tmp_path, monkeypatch,
                                              sample_db):
    """``--glob 'study/*/*.csv'`` over Sensor Logger exports matches every file of each: the
    folder reads the export, one walker named after it (each file was a walker, Metadata.csv a
    failed one); a CSV the app did not write stays a recording of its own."""
    from tests.test_sensorlog import _sensor_logger

    study = tmp_path / "study"
    study.mkdir()
    rec = simulate(next(c for c in sample_db.clips if c.name == WALKERS[0]), ["right_ankle"],
                   100.0, "phone", seed=5)
    for name, total in (("alice", False), ("bob", True)):
        _sensor_logger(study / name, rec, total=total, ios=False)
    (study / "alice" / "notes.csv").write_text("walker,note\nalice,limps\n")
    (study / "carol").mkdir()
    write_generic_csv(rec, study / "carol" / "carol.csv")
    found = find_recordings([study / "bob"], [str(study / "*" / "*.csv")])
    assert found == [study / "bob", study / "alice", study / "alice" / "notes.csv",
                     study / "carol" / "carol.csv"]
    assert output_names(found) == ["bob", "alice", "notes", "carol"]
    monkeypatch.chdir(study / "bob")  # bare names: the folder still has one
    assert output_names(find_recordings([], ["*.csv"])) == ["bob"]
    summary = run_batch(found[:2], tmp_path / "out", fitted=fitted, scheduler=client)
    assert [(r["name"], r["status"]) for r in summary["recordings"]] == [
        ("bob", "ok"), ("alice", "ok")]


def test_a_phyphox_folder_is_one_walker(fitted, client, tmp_path, sample_db):
    """``--glob 'study/**/*.csv'`` over unzipped phyphox exports matches their tables and
    ``meta/`` files: the folder reads the export, one walker named after it, dots and all
    (each file was a walker: Accelerometer.csv failed without a gyroscope, meta/device.csv as
    no sensor log, ...). Phyphox tables in a folder without ``meta/`` stay recordings of
    their own: they may be several walkers'."""
    from tests.test_sensorlog import _phyphox_rows

    study = tmp_path / "study"
    rec = simulate(next(c for c in sample_db.clips if c.name == WALKERS[0]), ["right_ankle"],
                   100.0, "phone", seed=5)
    acc, gyr = _phyphox_rows(rec)
    for name, meta in (("alice.day1", "device.csv"), ("bob", "time.csv")):
        (study / name / "meta").mkdir(parents=True)
        (study / name / "Accelerometer.csv").write_text(acc)
        (study / name / "Gyroscope.csv").write_text(gyr)
        (study / name / "meta" / meta).write_text('"property","value"\n"model","x"\n')
    (study / "loose").mkdir()
    (study / "loose" / "Accelerometer.csv").write_text(acc)
    found = find_recordings([], [str(study / "**" / "*.csv")])
    assert found == [study / "alice.day1", study / "bob", study / "loose" / "Accelerometer.csv"]
    assert output_names(found) == ["alice.day1", "bob", "Accelerometer"]
    summary = run_batch(found[:2], tmp_path / "out", fitted=fitted, scheduler=client)
    assert [(r["name"], r["status"]) for r in summary["recordings"]] == [
        ("alice.day1", "ok"), ("bob", "ok")]
    assert sorted(p.name for p in (tmp_path / "out").glob("*.json")) == [
        "alice.day1.json", "bob.json", "summary.json"]


def test_names_keep_a_folders_dots_and_never_collide(tmp_path, monkeypatch):
    """A folder's whole name is its own (Path.stem dropped what follows a dot: alice.day1 and
    alice.day2 were dots_alice and dots_alice_2, alone alice; ``.`` had no name and wrote
    ``.bvh``). ``summary`` is the batch's (summary.csv's report was replaced by the batch's
    summary.json, then refused as another's on a re-run). Names differing in case alone
    would be one file where case is ignored (macOS, Windows)."""
    def at(*names: str) -> list[Path]:
        return [tmp_path / n for n in names]

    for folder in at("dots/alice.day1", "dots/alice.day2"):
        folder.mkdir(parents=True)
    assert output_names(at("dots/alice.day1", "dots/alice.day2", "f/a.b.csv", "f/a.c.csv",
                           "f/log.csv.zip")) == ["alice.day1", "alice.day2", "a.b", "a.c",
                                                 "log.csv"]
    assert output_names(at("dots/alice.day1")) == ["alice.day1"]
    assert output_names(at("f/summary.csv", "f/walkers.csv")) == ["f_summary", "walkers"]
    assert output_names(at("a/Alice.csv", "b/alice.csv", "b/bob.csv")) == [
        "a_Alice", "b_alice", "bob"]
    assert output_names(at("a/x/log.csv", "b/x/LOG.csv")) == ["x_log", "x_LOG_2"]
    monkeypatch.chdir(tmp_path / "dots" / "alice.day1")
    assert output_names([Path("."), Path("log.csv")]) == ["alice.day1", "log"]


def test_strides_follow_the_strikes(sample_db):
    from imuloco.phases import gait_phases

    clip = next(c for c in sample_db.clips if c.name == WALKERS[0])
    ph = gait_phases(clip)
    rows = stride_rows(clip, ph, confidence=np.full(clip.num_frames, 0.05))
    n = sum(max(len(ph.steps[f]) - 1, 0) for f in ("left", "right"))
    assert len(rows) == n > 0 and all(tuple(r) == STRIDE_FIELDS for r in rows)
    for r in rows:
        assert r["end_s"] - r["start_s"] == pytest.approx(r["duration_s"], abs=2e-4)
        assert r["stance_s"] + r["swing_s"] == pytest.approx(r["duration_s"], abs=2e-4)
        assert 0 < r["stance_s"] < r["duration_s"] and r["confidence"] == 0.05
    # the median stride is the summary's ankle stride length (stride_length_m is speed-based)
    truth = gait_parameters(clip, ph)["ankle_stride_length_m"]
    assert np.median([r["length_m"] for r in rows]) == pytest.approx(truth, abs=1e-3)


def test_batch_writes_outputs_tables_and_error_rows(logs, fitted, client, tmp_path,
                                                    sample_db):
    paths, bad = logs
    summary = run_batch([*paths, bad], tmp_path, fitted=fitted, scheduler=client)
    assert (summary["done"], summary["skipped"], summary["failed"]) == (3, 0, 1)
    rows = summary["recordings"]
    assert [r["name"] for r in rows] == [*output_names(paths), "broken"]
    assert rows[-1]["status"] == "error" and "broken.csv" in rows[-1]["error"]
    assert not (tmp_path / "broken.bvh").exists() and not (tmp_path / "broken.json").exists()
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

    walkers = pq.read_table(tmp_path / "walkers.parquet")
    assert walkers.column_names == list(WALKER_FIELDS) and walkers.num_rows == 4
    assert str(walkers.schema.field("frames").type) == "int64"
    assert str(walkers.schema.field("speed_mps").type) == "double"
    w = walkers.to_pylist()
    assert [r["status"] for r in w] == ["ok"] * 3 + ["error"]
    assert w[0]["speed_mps"] == rows[0]["speed_mps"] and w[0]["method"] == "ridge"
    assert w[0]["placement"] == "right_ankle" and len(w[0]["model_sha256"]) == 64
    assert w[0]["height_m"] is None and w[3]["frames"] is None
    assert w[0]["mean_error_m"] is None and w[0]["unreliable_fraction"] is None  # ridge
    swings = [r["signal_swing_deg"] for r in w[:3]]  # a shin phone's, when it has a cadence
    assert [s is None for s in swings] == [r["signal_cadence_spm"] is None for r in w[:3]]
    assert any(swings) and all(40 < s < 100 for s in swings if s is not None)
    assert all(r["right_shank_swing_deg"] > 0 for r in w[:3] if r["signal_swing_deg"])
    strides = pq.read_table(tmp_path / "strides.parquet")
    assert strides.column_names == ["walker", *STRIDE_FIELDS]
    reported = sum(len(json.loads((tmp_path / f"{r['name']}.json").read_text())["strides"])
                   for r in rows[:3])
    assert strides.num_rows == summary["strides"] == reported > 10
    s = strides.to_pylist()
    assert {r["walker"] for r in s} == {r["name"] for r in rows[:3]}
    assert all(r["confidence"] is None for r in s)  # ridge gives none


def test_rerun_skips_complete_outputs_and_force_redoes(logs, fitted, client, tmp_path):
    paths, bad = logs
    first = run_batch(paths, tmp_path, fitted=fitted, scheduler=client)
    bvh = tmp_path / f"{first['recordings'][0]['name']}.bvh"
    stamp = bvh.stat().st_mtime_ns
    # an interrupted run: the third recording's JSON never got written
    (tmp_path / f"{first['recordings'][2]['name']}.json").unlink()
    again = run_batch([*paths, bad], tmp_path, fitted=fitted, scheduler=client)
    assert (again["done"], again["skipped"], again["failed"]) == (1, 2, 1)
    assert bvh.stat().st_mtime_ns == stamp  # not rewritten
    assert again["recordings"][:2] == first["recordings"][:2]  # the same rows, read back

    def timeless(row: dict) -> dict:
        return {k: v for k, v in row.items() if k != "seconds"}

    assert timeless(again["recordings"][2]) == timeless(first["recordings"][2])  # redone
    assert pq.read_table(tmp_path / "strides.parquet").num_rows == first["strides"]
    forced = run_batch(paths, tmp_path, fitted=fitted, scheduler=client, force=True)
    assert (forced["done"], forced["skipped"]) == (3, 0) and bvh.stat().st_mtime_ns != stamp
    # another model's outputs are never replaced without --force
    with pytest.raises(OutputExistsError, match="--force"):
        run_batch(paths, tmp_path, method="mean", scheduler=client)
    # a model fitted on the fly to the same state resumes (its training's time differs)
    means = run_batch(paths, tmp_path / "mean", method="mean", scheduler=client)
    again = run_batch(paths, tmp_path / "mean", method="mean", scheduler=client)
    assert (means["done"], again["done"], again["skipped"]) == (3, 0, 3)
    assert again["model_sha256"] == means["model_sha256"]
    # another height's are redone (they were skipped as complete, their lengths in the other
    # proportions)
    tall = run_batch(paths, tmp_path, fitted=fitted, scheduler=client, height_m=1.9)
    assert (tall["done"], tall["skipped"]) == (3, 0)
    again = run_batch(paths, tmp_path, fitted=fitted, scheduler=client, height_m=1.9)
    assert (again["done"], again["skipped"]) == (0, 3)


def test_a_walkers_file_gives_each_walker_its_height(logs, fitted, client, tmp_path, caplog):
    """--walkers on a scheduler: each walker's height reaches its skeleton, report and
    tables (an empty cell or no row: --height), the study's columns the tables (a walker of
    another batch is counted and left out); a re-run redoes only the walker whose height
    changed."""
    from imuloco.measures.gait import stature

    paths, _ = logs
    names = output_names(paths)
    model = fitted.save(tmp_path / "ridge.npz")
    study = tmp_path / "walkers.csv"
    study.write_text(f"name,height_m,age\n{names[0]},1.6,31\n{names[1]},,45\nzed,1.5,50\n")
    out = tmp_path / "out"
    args = ["batch", *map(str, paths), "--out", str(out), "--model", str(model),
            "--scheduler", client.scheduler.address, "--walkers", str(study), "--height", "1.9"]
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 0, res.output
    warned = [r.getMessage() for r in caplog.records if r.name == "imuloco.app.walkers"]
    assert warned == [f"{study}: 1 walker has no recording in this batch",
                      (f"{study}: no row for 1 recording(s) of this batch, which get the "
                       f"default height (--height, else the model skeleton's): {names[2]}")]
    expected = [1.6, 1.9, 1.9]

    def heights() -> list[float]:
        return [stature(read_bvh(out / f"{n}.bvh", unit="cm").skeleton) for n in names]

    assert heights() == pytest.approx(expected, abs=0.01)
    assert [json.loads((out / f"{n}.json").read_text())["batch"]["height_m"]
            for n in names] == expected
    with open(out / "summary.csv") as f:
        table = list(csv.DictReader(f))
    assert [(float(t["height_m"]), t["age"]) for t in table] == [
        (1.6, "31"), (1.9, "45"), (1.9, "")]
    w = pq.read_table(out / "walkers.parquet")
    assert w.column_names == [*WALKER_FIELDS, "age"]
    assert w.column("height_m").to_pylist() == expected
    assert w.column("age").to_pylist() == [31, 45, None]
    stamps = [(out / f"{n}.bvh").stat().st_mtime_ns for n in names]
    study.write_text(f"name,height_m,age\n{names[0]},1.6,31\n{names[1]},1.7,45\n")
    again = run_batch(paths, out, fitted=fitted, scheduler=client, height_m=1.9,
                      walkers=study)
    assert (again["done"], again["skipped"]) == (1, 2)
    assert [r["height_m"] for r in again["recordings"]] == [1.6, 1.7, 1.9]
    assert heights() == pytest.approx([1.6, 1.7, 1.9], abs=0.01)
    assert [(out / f"{n}.bvh").stat().st_mtime_ns == t for n, t in zip(names, stamps)] == [
        True, False, True]
    # a typo is refused before any work, naming the file, line and the name meant
    study.write_text(f"name,height_m\n{names[0]}x,1.6\n")
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 1 and f"{study}:2: name '{names[0]}x'" in res.output
    assert f"close: '{names[0]}'" in res.output


def test_a_walker_redone_for_another_height_is_incomplete_until_done(logs, fitted, client,
                                                                    tmp_path, monkeypatch):
    """Its BVH written, its report not: the earlier height's report must not mark it
    complete (a re-run at that height would keep the BVH of the other)."""
    from imuloco.io.atomic import OutputSet

    paths, _ = logs
    run_batch(paths[:1], tmp_path, fitted=fitted, scheduler=client, height_m=1.6)
    real = OutputSet.open

    def no_report(self, path, *args, **kwargs):  # workers are threads of this process
        if Path(path).suffix == ".json":
            raise OSError(28, "No space left on device")
        return real(self, path, *args, **kwargs)

    monkeypatch.setattr(OutputSet, "open", no_report)
    assert run_batch(paths[:1], tmp_path, fitted=fitted, scheduler=client,
                     height_m=1.8)["failed"] == 1
    monkeypatch.undo()
    again = run_batch(paths[:1], tmp_path, fitted=fitted, scheduler=client, height_m=1.6)
    assert (again["done"], again["skipped"]) == (1, 0)


def test_a_failed_write_leaves_no_partial_file(logs, fitted, client, tmp_path, monkeypatch):
    import pyarrow.parquet

    from imuloco.errors import ImulocoError

    paths, _ = logs
    run_batch(paths[:1], tmp_path, fitted=fitted, scheduler=client)
    before = (tmp_path / "walkers.parquet").read_bytes()
    real_write = pyarrow.parquet.write_table

    def disk_full(table, where, **kw):  # half a file, then the disk is full
        real_write(table, where, **kw)
        where.truncate(where.tell() // 2)
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(pyarrow.parquet, "write_table", disk_full)
    with pytest.raises(ImulocoError, match="no space left on device writing"):
        run_batch(paths[:2], tmp_path, fitted=fitted, scheduler=client)
    assert (tmp_path / "walkers.parquet").read_bytes() == before
    assert not [p.name for p in tmp_path.iterdir() if p.name.startswith(".")]
    # the second walker's own outputs were complete before the tables failed: a re-run
    # keeps them
    monkeypatch.undo()
    again = run_batch(paths[:2], tmp_path, fitted=fitted, scheduler=client)
    assert (again["done"], again["skipped"]) == (0, 2)


def test_a_recording_failing_mid_write_leaves_no_partial_bvh(logs, fitted, client, tmp_path,
                                                             monkeypatch):
    from imuloco.io import bvh

    paths, _ = logs
    real = bvh.to_euler

    def fail(*a, **kw):
        raise MemoryError("simulated failure while writing")

    monkeypatch.setattr(bvh, "to_euler", fail)  # workers are threads of this process
    summary = run_batch(paths[:1], tmp_path, fitted=fitted, scheduler=client)
    assert summary["failed"] == 1 and "simulated failure" in summary["recordings"][0]["error"]
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "strides.parquet", "summary.csv", "summary.json", "walkers.parquet"]
    monkeypatch.setattr(bvh, "to_euler", real)


def test_cli_batch_on_a_local_cluster_of_processes(logs, fitted, tmp_path):
    paths, _ = logs
    model = fitted.save(tmp_path / "ridge.npz")
    out = tmp_path / "out"
    args = ["batch", str(paths[2]), "--glob", str(paths[0].parent / "*.csv"), "--out",
            str(out), "--model", str(model), "--jobs", "1"]
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 0, res.output
    assert "2 done, 0 skipped, 0 failed of 2" in res.output and "recordings/min" in res.output
    assert (out / f"{WALKERS[2]}.bvh").exists() and (out / "phone.bvh").exists()
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 0 and "0 done, 2 skipped, 0 failed" in res.output
    res = CliRunner().invoke(cli, ["batch", "--out", str(out)])
    assert res.exit_code == 2 and "no recordings" in res.output


def test_cli_batch_on_a_scheduler_reports_failures(logs, fitted, client, tmp_path):
    _, bad = logs
    model = fitted.save(tmp_path / "ridge.npz")
    res = CliRunner().invoke(cli, ["batch", str(bad), "--out", str(tmp_path / "bad"),
                                   "--model", str(model), "--scheduler",
                                   client.scheduler.address])
    assert res.exit_code == 1 and "0 done, 0 skipped, 1 failed" in res.output
    assert "1 recording(s) failed" in res.output


def test_benchmark_walkers_are_continuous_and_seeded(sample_db):
    from imuloco.lab.batchbench import WALKING, walker_motion
    from imuloco.ops.heading import heading_from_hips, wrap_angle

    clips = [c for c, lab in zip(sample_db.clips, sample_db.labels)
             if lab["content"] in WALKING]
    m = walker_motion(clips, 60.0, seed=3)
    assert m.num_frames == 1800 and m.fps == 30.0
    # chained clips start where and facing where the last one ended: no jump at a seam
    step = np.linalg.norm(np.diff(m.root[:, [0, 2]], axis=0), axis=1)
    assert step.max() < 0.1  # m per frame: 3 m/s
    hips = m.part_positions(["left_hip", "right_hip"])
    turn = np.abs(wrap_angle(np.diff(heading_from_hips(hips[:, 0], hips[:, 1]))))
    assert np.degrees(turn.max()) < 20
    again, other = walker_motion(clips, 60.0, seed=3), walker_motion(clips, 60.0, seed=4)
    np.testing.assert_array_equal(again.rotations, m.rotations)
    assert not np.array_equal(other.root, m.root)


def test_a_worker_lost_mid_task_is_retried_elsewhere(logs, fitted, tmp_path, monkeypatch):
    """The first reconstruction closes the worker running it: Dask reschedules the task on
    the other worker and the recording completes."""
    import time

    from distributed.core import Status

    from imuloco.app import batch

    paths, _ = logs
    real, calls = batch.reconstruct_file, []

    def lose_worker(*args, **kwargs):
        calls.append(distributed.get_worker().address)
        if len(calls) == 1:
            worker = distributed.get_worker()
            worker.loop.add_callback(worker.close, executor_wait=False)
            deadline = time.monotonic() + 60
            while worker.status != Status.closed and time.monotonic() < deadline:
                time.sleep(0.05)
        return real(*args, **kwargs)

    monkeypatch.setattr(batch, "reconstruct_file", lose_worker)  # where batch looks it up
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  **LOCAL_CLUSTER) as cluster, \
            distributed.Client(cluster) as c:
        summary = run_batch(paths[:1], tmp_path, fitted=fitted, scheduler=c)
    assert len(calls) == 2 and calls[0] != calls[1]
    assert summary["done"] == 1 and summary["failed"] == 0
    assert read_bvh(tmp_path / f"{summary['recordings'][0]['name']}.bvh").num_frames > 0


def test_a_second_run_on_one_folder_is_refused_naming_the_first(logs, fitted, client, tmp_path,
                                                                caplog):
    """Two runs on one --out both reported "8 done" with their units mixed; the second is
    refused before any work, and a dead run's lock is taken over with a warning."""
    import os
    import socket
    import subprocess
    import sys

    from imuloco.errors import ImulocoError
    from imuloco.io.folderlock import LOCK_NAME, FolderLock

    paths, _ = logs
    holder = rf"another run \(host {socket.gethostname()}, pid {os.getpid()}, started"
    with FolderLock(tmp_path), pytest.raises(ImulocoError, match=holder):
        run_batch(paths, tmp_path, fitted=fitted, scheduler=client)
    assert [p.name for p in tmp_path.iterdir()] == []  # released: the lock file is gone
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (tmp_path / LOCK_NAME).write_text(json.dumps({"host": socket.gethostname(),
                                                  "pid": dead.pid, "started": "then"}))
    summary = run_batch(paths[:1], tmp_path, fitted=fitted, scheduler=client)
    assert summary["done"] == 1 and "taking over the lock of a run that died" in caplog.text
    (tmp_path / LOCK_NAME).write_text(json.dumps({"host": "elsewhere", "pid": 1,
                                                  "started": "now"}))
    with pytest.raises(ImulocoError, match=r"host elsewhere, pid 1.*remove .*\.imuloco\.lock"):
        run_batch(paths[:1], tmp_path, fitted=fitted, scheduler=client)


def test_a_new_bvh_beside_an_old_report_is_not_complete(logs, fitted, client, tmp_path):
    """kill -9 between writing a recording's BVH and its report left a new BVH beside an old
    report, which a re-run took as complete: the report names its BVH's SHA-256."""
    from imuloco.io.atomic import sha256_file

    paths, _ = logs
    first = run_batch(paths[:2], tmp_path, fitted=fitted, scheduler=client)
    name = first["recordings"][0]["name"]
    report = json.loads((tmp_path / f"{name}.json").read_text())
    assert report["batch"]["bvh_sha256"] == sha256_file(tmp_path / f"{name}.bvh")
    other = tmp_path / f"{first['recordings'][1]['name']}.bvh"
    (tmp_path / f"{name}.bvh").write_bytes(other.read_bytes())  # another run's BVH
    again = run_batch(paths[:2], tmp_path, fitted=fitted, scheduler=client)
    assert (again["done"], again["skipped"]) == (1, 1)
    assert json.loads((tmp_path / f"{name}.json").read_text())["batch"]["bvh_sha256"] == \
        sha256_file(tmp_path / f"{name}.bvh") != sha256_file(other)


def test_only_regular_files_and_no_link_loops(logs, tmp_path):
    """A FIFO named .csv hung batch for ever; a link loop under --glob '**' made one recording
    into 41 walkers (two loops in one folder: 2**40 paths)."""
    import os

    from imuloco.errors import InputError

    paths, _ = logs
    study = tmp_path / "study"
    (study / "a").mkdir(parents=True)
    (study / "a" / "walk.csv").write_bytes(paths[0].read_bytes())
    (study / "a" / "loop").symlink_to(study)
    (study / "a" / "loop2").symlink_to(study / "a")
    (study / "same.csv").symlink_to(study / "a" / "walk.csv")
    os.mkfifo(study / "stuck.csv")
    found = find_recordings([], [str(study / "**" / "*.csv")])
    assert found == [study / "a" / "walk.csv"]
    with pytest.raises(InputError, match="stuck.csv: not a regular file"):
        find_recordings([study / "stuck.csv"])


def test_a_stuck_recording_becomes_an_error_row(logs, fitted, client, tmp_path, monkeypatch):
    """A recording that never finishes is an error row after the time limit; the others are
    done."""
    import threading

    from imuloco.app import batch

    paths, _ = logs
    release = threading.Event()
    real = batch.reconstruct_file

    def stuck_on_the_first(recording, **kw):
        if Path(recording) == paths[0].absolute() and release.wait(60):
            raise RuntimeError("released")  # as a read from a FIFO that never ends
        return real(recording, **kw)

    monkeypatch.setattr(batch, "reconstruct_file", stuck_on_the_first)
    summary = run_batch(paths[:2], tmp_path, fitted=fitted, scheduler=client, timeout_s=2.0)
    release.set()
    rows = summary["recordings"]
    assert [r["status"] for r in rows] == ["error", "ok"]
    assert "TimeoutError: no result after 2 s" in rows[0]["error"]


def test_batch_never_reads_its_own_outputs_and_relays_its_workers_warnings(
        fitted, client, tmp_path, sample_db, caplog):
    """A re-run with ``--glob '*/*.csv'`` over a study whose --out is among the folders leaves
    out the batch's own summary.csv; a Sensor Logger export without Metadata.csv warns that
    Android is assumed, in the walker's report and on the batch's log (relayed from the
    worker, where no one reads it)."""
    from tests.test_sensorlog import _sensor_logger

    rec = simulate(next(c for c in sample_db.clips if c.name == WALKERS[0]), ["right_ankle"],
                   100.0, "phone", seed=5)
    _sensor_logger(tmp_path / "alice", rec, total=True, ios=False)
    (tmp_path / "alice" / "Metadata.csv").unlink()
    out = tmp_path / "out"
    with caplog.at_level("WARNING"):
        run_batch(find_recordings([], [str(tmp_path / "*" / "*.csv")], out_dir=out), out,
                  fitted=fitted, scheduler=client)
    assert (out / "summary.csv").is_file()
    report = json.loads((out / "alice.json").read_text())
    assert any("assuming Android" in w for w in report["warnings"])
    relayed = [r for r in caplog.records if r.name == "imuloco.app.batch"]
    assert any(r.getMessage().startswith("alice: ") and "assuming Android" in r.getMessage()
               for r in relayed)
    caplog.clear()
    with caplog.at_level("WARNING"):
        again = find_recordings([], [str(tmp_path / "*" / "*.csv")], out_dir=out)
    assert again == [tmp_path / "alice"]
    assert "left out 1 file(s) this batch writes" in caplog.text and "summary.csv" in caplog.text
    assert find_recordings([out / "summary.csv"]) == [out / "summary.csv"]  # no out_dir: kept
