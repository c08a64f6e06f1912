"""The speed benchmark: database building and the records it writes (timings not asserted)."""

from __future__ import annotations

import json

import pytest

from imuloco.lab.speed import build_database, speed_benchmark, speed_table

KEYS = {"method", "db_frames", "online_fps", "online_latency_ms_p50", "online_latency_ms_p99"}


def test_build_database_sizes_and_repeats(sample_db):
    small, info = build_database(sample_db, 500)
    assert 500 - 60 <= info["db_frames"] <= 500 and info["db_frames"] == small.num_frames
    assert not info["repeated"]
    big, info = build_database(sample_db, 3 * sample_db.num_frames)
    assert info["repeated"] and info["distinct_frames"] <= sample_db.num_frames
    names = [lab["name"] for lab in big.labels]
    assert len(set(names)) == len(names)          # copies get their own noise seeds
    assert abs(info["db_frames"] - 3 * sample_db.num_frames) <= 60
    again, _ = build_database(sample_db, 500)
    assert [lab["name"] for lab in again.labels] == [lab["name"] for lab in small.labels]


def test_speed_benchmark_writes_records(tmp_path):
    records = speed_benchmark(["mousas2017", "mean"], tmp_path, None, [400])
    assert [r["method"] for r in records] == ["mousas2017", "mean"]
    for r in records:
        assert KEYS <= set(r)
        assert r["online_fps"] > 0 and r["online_latency_ms_p99"] >= r["online_latency_ms_p50"]
        assert r["steps"] >= 300
    assert records[0]["states"] > 0
    on_disk = json.loads((tmp_path / "speed.json").read_text())
    assert [r["db_frames"] for r in on_disk] == [r["db_frames"] for r in records]
    md = (tmp_path / "speed.md").read_text()
    assert md == speed_table(records) + "\n" and "mousas2017" in md


def test_speed_benchmark_rejects_unknown_methods(tmp_path):
    with pytest.raises(KeyError, match="unknown"):
        speed_benchmark(["no-such-method"], tmp_path, None, [400])


def test_speed_benchmark_times_stream_variants_on_one_fit(tmp_path):
    """Specs differing only in stream hyperparameters share the fitted model; each has its
    own record with the test clip's MPJPE; a full beam and the numpy engine stream as the
    exact (compiled) step."""
    from imuloco.methods.mousas2017.method import Mousas2017

    assert Mousas2017.stream_params == ("beam", "engine")
    specs = ["mousas2017", "mousas2017[beam=100000]", "mousas2017[beam=3]",
             "mousas2017[engine=numpy]"]
    records = speed_benchmark(specs, tmp_path, None, [400])
    assert [r["method"] for r in records] == specs
    assert len({r["fit_s"] for r in records}) == 1 and len({r["states"] for r in records}) == 1
    exact, full, narrow, numpy_step = (r["test_mpjpe_cm"] for r in records)
    assert exact == pytest.approx(full, abs=1e-3) and narrow > 0
    assert exact == pytest.approx(numpy_step, abs=1e-6)
    assert "mousas2017[beam=3]" in (tmp_path / "speed.md").read_text()


def test_offline_methods_are_timed_and_scored(tmp_path):
    records = speed_benchmark(["mean"], tmp_path, None, [400])
    r = records[0]
    assert r["offline_fps"] > 0 and r["offline_fps_cpu"] > 0
    # the mean pose is far from a walking clip, and MPJPE is positive and finite
    assert 1.0 < r["test_mpjpe_cm"] < 50.0


def test_against_a_commit_fits_that_commits_code(tmp_path):
    """``against`` runs the method's module as it was at a commit beside today's, on the
    same database and test clip: at HEAD both give the same reconstruction."""
    import subprocess
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    if subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"],
                      check=False, capture_output=True).returncode != 0:
        pytest.skip("needs a git checkout")
    records = speed_benchmark(["ridge"], tmp_path, None, [400], against="HEAD")
    assert [r["method"] for r in records] == ["ridge", "ridge@HEAD"]
    assert records[0]["test_mpjpe_cm"] == pytest.approx(records[1]["test_mpjpe_cm"], abs=1e-9)
    with pytest.raises(ValueError, match="no-such-rev"):
        speed_benchmark(["ridge"], tmp_path, None, [400], against="no-such-rev")
    # a method package: its module's names from the package's other modules come from the
    # commit too (mousas2017's stream, forward step and model); stream hyperparameters
    # (beam) are left out of the old code's run
    records = speed_benchmark(["mousas2017[beam=100000]"], tmp_path, None, [400],
                              against="HEAD")
    assert [r["method"] for r in records] == ["mousas2017[beam=100000]", "mousas2017@HEAD"]
    assert records[0]["test_mpjpe_cm"] == pytest.approx(records[1]["test_mpjpe_cm"], abs=1e-3)


def test_a_walk_log_lasts_what_was_asked(tmp_path):
    """The reconstruct row's simulated walks: clips end to end, times rising, the length
    asked for (to a sample), at 100 Hz."""
    from imuloco.lab.speed import walk_log
    from imuloco.sensors.reallog import read_log

    log = walk_log("right_ankle", 25.0, tmp_path / "walk.csv")
    rec, _ = read_log(log, placement="right_ankle")
    assert rec.times[-1] - rec.times[0] == pytest.approx(25.0, abs=0.02)
    assert len(rec.times) == pytest.approx(2500, abs=3)


def test_reconstruct_table_and_bvh_difference(spinning_motion, tmp_path):
    from imuloco.io.bvh import write_bvh
    from imuloco.lab.speed import bvh_difference, reconstruct_table

    a = write_bvh(spinning_motion, tmp_path / "a.bvh")
    moved = spinning_motion.copy()
    moved.root = moved.root + [0.0, 0.0, 0.25]
    b = write_bvh(moved, tmp_path / "b.bvh")
    assert bvh_difference(a, a) == 0.0
    assert bvh_difference(a, b) == pytest.approx(25.0, abs=1e-3)  # cm
    row = {"placement": "right_ankle", "length_s": 60.0, "threads": "1", "code": "today",
           "wall_s": 2.0, "cpu_s": 1.5, "realtime": 30.0, "realtime_cpu": 40.0,
           "peak_rss_mb": 300.0, "load_avg": 1.0}
    text = reconstruct_table([row, {**row, "code": "abc", "max_diff_cm": 0.01}])
    assert "| right_ankle | 60 | 1 | today | 2.0 | 1.5 | 30 | 40 | 300 | - | 1.0 |" in text
    assert "| 0.01 |" in text
