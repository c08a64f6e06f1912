"""The fuzz harness of `imuloco bench --fuzz`: outcomes judged as the issue defines them."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from imuloco.cli import cli
from imuloco.lab.fuzz import OUTCOMES, judge


def test_judge_tells_clean_from_foreign_and_accepted(tmp_path, sample_db):
    from imuloco.methods import get_method

    (tmp_path / "some.csv").write_text("time_s,acc_x\n0,1\n")
    assert judge("model", [tmp_path / "some.csv"])[0] == "clean"
    model = get_method("mean").fit(sample_db.subset([0]), ["right_ankle"], "phone", 0)
    assert judge("model", [model.save(tmp_path / "m.npz")]) == ("accepted", "")
    (tmp_path / "x.bvh").write_text("HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\n")
    outcome, detail = judge("bvh", [tmp_path / "x.bvh"])
    assert outcome == "clean" and "x.bvh" in detail


def test_bench_fuzz_writes_the_table(tmp_path):
    result = CliRunner().invoke(cli, ["bench", "--fuzz", "6", "--readers", "sensorlog,model",
                                      "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    data = json.loads((tmp_path / "fuzz.json").read_text())["results"]
    for reader in ("sensorlog", "model"):
        assert sum(data[reader][o] for o in OUTCOMES) == data[reader]["inputs"] == 6
    assert "| sensor-log tables | 6 |" in (tmp_path / "fuzz.md").read_text()


def test_fuzzed_real_data_folders_end_in_clean_errors():
    """The real-data layouts (pyshoe-vicon, ipol-gait, mobilise-d-lab): generated malformed
    folders are read or refused with the library's own error, none hangs or is implausible."""
    from imuloco.lab.fuzz import run_fuzz

    r = run_fuzz(150, ("real",))["real"]
    assert r["wrong exception type"] == r["hang"] == r["garbage accepted"] == 0, r["examples"]
    assert r["clean"] > 50 and r["accepted"] > 5  # both outcomes are exercised


def test_fuzzed_xsens_exports_end_in_clean_errors():
    """Xsens text exports (MT Manager, the DOT app, ipol-gait) through read_log: generated
    malformed files are read or refused with the library's own error, none hangs or is
    implausible (before the xsens seed the fuzzer never read one)."""
    from imuloco.lab.fuzz import run_fuzz

    r = run_fuzz(150, ("xsens",))["xsens"]
    assert r["wrong exception type"] == r["hang"] == r["garbage accepted"] == 0, r["examples"]
    assert r["clean"] > 50 and r["accepted"] > 5  # both outcomes are exercised


def test_fuzzed_model_headers_are_refused_or_sound(tmp_path):
    """Huge ints, NaN, Infinity, other types and deep nests anywhere in a saved model's JSON
    header (issue 42: 9, 13): each refused naming the file, or loaded with its parameters in
    the method's table and no non-finite learned value (judged in this process: the time
    limit is the bench's, ``imuloco bench --fuzz N --readers model_header``)."""
    from imuloco.lab.fuzz import cases, judge, seed_files

    seeds = seed_files(tmp_path)["model_header"]
    outcomes = []
    for i, case in enumerate(cases("model_header", seeds, 16, seed=1)):
        folder = tmp_path / f"case{i}"
        folder.mkdir()
        paths = []
        for name, data in case.files:
            (folder / name).write_bytes(data)
            paths.append(folder / name)
        outcome, detail = judge("model_header", paths)
        assert outcome in ("clean", "accepted"), (case.mutation, outcome, detail)
        outcomes.append(outcome)
    assert "clean" in outcomes


def test_fuzzed_structures_zip_members_and_output_targets_end_cleanly():
    """Issue 42's classes: structure-aware BVH/AMC, zip-member bombs and output targets (a
    FIFO, a link to /proc/self/fd/1, a device node, two outputs at one path) are read or
    refused with the library's own error; none hangs, none is replaced or accepted wrongly."""
    from imuloco.lab.fuzz import run_fuzz

    readers = ("bvh-structure", "amc-structure", "zip-members", "outputs")
    results = run_fuzz(30, readers, timeout=20.0)
    for reader in readers:
        r = results[reader]
        assert r["wrong exception type"] == r["hang"] == r["garbage accepted"] == 0, \
            (reader, r["examples"])
        assert r["clean"] > 5 and r["accepted"] > 0, (reader, r)  # both outcomes exercised


def test_the_output_fuzzer_sees_a_replaced_fifo_as_garbage(tmp_path, monkeypatch):
    """The judge of output targets counts a FIFO replaced by a regular file as garbage (as
    today's writer did before it checked)."""
    import json

    from imuloco.io import atomic

    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps({"kind": "fifo"}))
    assert judge("outputs", [spec])[0] == "clean"
    (tmp_path / "a.bvh").unlink()
    monkeypatch.setattr(atomic, "_check_kind", lambda path: None)
    outcome, detail = judge("outputs", [spec])
    assert outcome == "garbage accepted" and "replaced" in detail, detail


@pytest.fixture(scope="module")
def watch_seeds(sample_db, tmp_path_factory):
    from imuloco.lab.fuzz_watch import watch_seeds

    walk = sample_db.where(content="walk").clips[0]
    return watch_seeds(walk, tmp_path_factory.mktemp("watch"))


def _written(folder, files) -> list:
    paths = []
    for name, data in files:
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_bytes(data)
        paths.append(folder / name)
    return paths


def test_fuzzed_watch_exports_and_sensor_pairs_end_cleanly(tmp_path, watch_seeds):
    """A second sensor (issue 46): Sensor Logger exports with the watch's WristMotion.csv and
    ``--sensor`` pairs on clocks of their own, mutated, are read or refused with the library's
    own error, none implausible or accepted with a wrong clock offset (judged in this
    process: the time limit is the bench's, ``imuloco bench fuzz N --readers watch``)."""
    from imuloco.lab.fuzz import cases, judge

    outcomes = []
    for i, case in enumerate(cases("watch", watch_seeds, 40, seed=2)):
        outcome, detail = judge("watch", _written(tmp_path / f"case{i}", case.files))
        assert outcome in ("clean", "accepted"), (case.mutation, outcome, detail)
        outcomes.append(outcome)
    assert outcomes.count("clean") > 5 and outcomes.count("accepted") > 5


def test_the_watch_fuzzer_sees_a_wrong_clock_offset_as_garbage(tmp_path, watch_seeds):
    """The pair's judge: a reading accepted with the watch's clock off by more than a frame
    from the truth its folder names is garbage (as the old first-jolt rule's 2.37 s was)."""
    from imuloco.lab.fuzz import judge
    from imuloco.lab.fuzz_watch import SEED_OFFSET_S

    pair = [(name.replace(f"{SEED_OFFSET_S:+.3f}", "+0.500"), data)
            for name, data in watch_seeds[2].items()]
    outcome, detail = judge("watch", _written(tmp_path, pair))
    assert outcome == "garbage accepted" and "true offset is +0.500" in detail, detail
    assert judge("watch", _written(tmp_path, watch_seeds[2].items()))[0] == "accepted"
