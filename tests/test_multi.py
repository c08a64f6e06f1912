"""Several sensors: the watch of a Sensor Logger export, --sensor files on one clock, the
refusal of sensors recorded apart, the model that reads them all, simulate -> reconstruct."""

from __future__ import annotations

import json
import logging
import shutil

import numpy as np
import pytest
from click.testing import CliRunner

from imuloco.cli import cli
from imuloco.core.recording import Recording
from imuloco.errors import FormatError
from imuloco.io.sensorlog import WATCH_FILE, write_generic_csv
from imuloco.io.sensorwrite import write_sensor_files, write_sensor_logger
from imuloco.sensors.multi import read_sensors
from imuloco.sensors.reallog import check_overlap, read_log
from imuloco.sensors.simulate import STOMP_AT_S, STOMP_LEAD_S, simulate, still_start

PAIR = ["right_ankle", "left_wrist"]
FRAME_S = 1 / 30
UNIX = 1.7e9


@pytest.fixture(scope="module")
def walk(sample_db):
    return next(c for c in sample_db.clips if c.name == "dataset-2_walk_normal_001")


@pytest.fixture(scope="module")
def pair_rec(walk):
    return simulate(walk, PAIR, noise="phone", seed=2)


@pytest.fixture(scope="module")
def pair_model(sample_db, tmp_path_factory):
    """ridge reading the shin and the watch, saved as a file."""
    from imuloco.methods import get_method

    walks = sample_db.where(content=["walk"])
    model = get_method("ridge").fit(walks.subset([0, 1, 2]), PAIR, "phone", 0)
    return model.save(tmp_path_factory.mktemp("models") / "ridge_right_ankle+left_wrist.npz")


# ---- the watch in a Sensor Logger export ----------------------------------------------------
def _same_signals(a: Recording, b: Recording, acc_tol: float = 0.01) -> None:
    n = min(a.num_samples, b.num_samples)
    assert a.placements == b.placements
    assert np.abs(a.acc[:n] - b.acc[:n]).max() < acc_tol
    assert np.abs(a.gyro[:n] - b.gyro[:n]).max() < 1e-3


def test_wrist_motion_is_read_as_a_second_sensor(tmp_path, pair_rec):
    write_sensor_logger(pair_rec, tmp_path / "export")
    rec, report = read_log(tmp_path / "export")
    reference, _ = read_log(write_generic_csv(pair_rec, tmp_path / "same.csv"))
    _same_signals(rec, reference)  # the iOS sign and g units undone, gravity added back
    assert [s.placement for s in report.sensors] == PAIR
    assert report.sensors[1].file.endswith(WATCH_FILE)
    assert report.sensors[1].aligned_by == "timestamps" and report.sensors[1].offset_s == 0
    shutil.make_archive(str(tmp_path / "export"), "zip", tmp_path / "export")  # the shared zip
    _same_signals(read_log(tmp_path / "export.zip")[0], reference)


def test_wrist_motion_with_standardised_units_and_frames(tmp_path, pair_rec):
    """"Standardise Units & Frames" on: m/s^2 and Android's sign, told by gravity's size."""
    folder = tmp_path / "export"
    write_sensor_logger(pair_rec, folder)
    text = (folder / WATCH_FILE).read_text().splitlines()
    header = text[0].split(",")
    cols = [i for i, h in enumerate(header) if h[:-1] in ("gravity", "acceleration")]
    rows = []
    for line in text[1:]:
        cells = line.split(",")
        for i in cols:
            cells[i] = repr(-9.80665 * float(cells[i]))
        rows.append(",".join(cells))
    (folder / WATCH_FILE).write_text("\n".join([text[0], *rows]) + "\n")
    rec, _ = read_log(folder)
    _same_signals(rec, read_log(write_generic_csv(pair_rec, tmp_path / "same.csv"))[0])


def test_a_phone_at_the_watchs_placement_is_refused(tmp_path, pair_rec):
    write_sensor_logger(pair_rec, tmp_path / "export")
    with pytest.raises(FormatError, match="left_wrist.*WristMotion.csv"):
        read_log(tmp_path / "export", placement="left_wrist")


# ---- --sensor files on one clock ------------------------------------------------------------
@pytest.mark.parametrize("offset", [-2.0, -0.77, 1.31, 2.0])
def test_misaligned_clocks_are_found_within_a_frame(tmp_path, walk, offset):
    late = max(offset, 0.0)  # the stomps come after the late device started
    rec = simulate(still_start(walk, STOMP_LEAD_S + late), PAIR, noise="phone", seed=1,
                   stomps=[late + t for t in STOMP_AT_S])
    files = write_sensor_files(rec, tmp_path, {"left_wrist": offset})
    merged, report = read_sensors(files[0], [("left_wrist", files[1])])
    source = report.sensors[1]
    assert source.aligned_by == "xcorr" and source.correlation > 0.9
    assert abs(source.offset_s - offset) < FRAME_S
    # the wrist's signal lands where the true one is: against the simulation's own
    truth, _ = read_log(write_generic_csv(rec, tmp_path / "truth.csv"))
    k = np.searchsorted(truth.times, merged.times[100:-100] + report.start_time)
    assert np.median(np.abs(merged.acc[100:-100, 1] - truth.acc[k, 1])) < 0.5


@pytest.fixture(scope="module")
def run(sample_db):
    return next(c for c in sample_db.clips if c.name == "dataset-2_run_normal_001")


def _stomped_files(tmp_path, motion, clocks, stomps=STOMP_AT_S, wrist_stomps=None):
    """One file per sensor of PAIR after a stand with two stomps (the wrist's at
    ``wrist_stomps`` if given), each device's clock ``clocks[placement]`` s behind."""
    late = max(0.0, *clocks.values())  # the stand and stomps after the late device started
    still = still_start(motion, STOMP_LEAD_S + late)
    rec = simulate(still, PAIR, noise="phone", seed=3, stomps=[late + t for t in stomps])
    if wrist_stomps is not None:
        wrist = simulate(still, PAIR, noise="phone", seed=3,
                         stomps=[late + t for t in wrist_stomps])
        rec.acc[:, 1] = wrist.acc[:, 1]
    return write_sensor_files(rec, tmp_path, clocks)


@pytest.mark.parametrize("clocks, offset", [({"left_wrist": 2.0}, 2.0),
                                            ({"right_ankle": 1.6}, -1.6)])
def test_stomps_before_a_run_align_either_device_starting_first(tmp_path, run, clocks, offset):
    """A run starting right after the stomps (its steps jolt more than the stand's noise
    everywhere: the stomps must be told from them), the watch or the phone started late."""
    files = _stomped_files(tmp_path, run, clocks)
    _, report = read_sensors(files[0], [("left_wrist", files[1])])
    assert abs(report.sensors[1].offset_s - offset) < FRAME_S
    assert report.sensors[1].correlation > 0.9


def test_clocks_without_stomps_are_refused(tmp_path, run):
    rec = simulate(still_start(run, STOMP_LEAD_S + 1.0), PAIR, noise="phone", seed=3)
    files = write_sensor_files(rec, tmp_path, {"left_wrist": 1.0})
    with pytest.raises(FormatError, match="could not be aligned.*no two stomps found.*stomp "
                                          "twice"):
        read_sensors(files[0], [("left_wrist", files[1])])


def test_stomps_spaced_apart_differently_are_refused(tmp_path, walk):
    """Two stomps on each sensor, but not the same two (0.7 s apart on the shin, 1.1 s on
    the wrist): no offset makes both agree."""
    files = _stomped_files(tmp_path, walk, {"left_wrist": 0.5}, wrist_stomps=(0.5, 1.6))
    with pytest.raises(FormatError, match=r"stomps are 0.7\d s apart in the first file, "
                                          r"1.1\d s"):
        read_sensors(files[0], [("left_wrist", files[1])])


def _unix_file(path, rec: Recording, start: float, stop: float):
    keep = (rec.times >= start) & (rec.times <= stop)
    part = Recording(rec.times[keep] + UNIX, rec.acc[keep], rec.gyro[keep], rec.placements)
    return write_generic_csv(part, path)


def test_unix_clocks_are_aligned_by_their_timestamps(tmp_path, pair_rec):
    shin = _unix_file(tmp_path / "shin.csv", pair_rec.select(["right_ankle"]), 0.0, 9.0)
    watch = _unix_file(tmp_path / "watch.csv", pair_rec.select(["left_wrist"]), 1.0, 8.5)
    merged, report = read_sensors(shin, [("left_wrist", watch)])
    assert report.sensors[1].aligned_by == "timestamps" and report.sensors[1].offset_s == 0
    assert report.start_time == pytest.approx(UNIX + 1.0, abs=0.02)
    together, _ = read_log(write_generic_csv(pair_rec, tmp_path / "both.csv"))
    k = np.searchsorted(together.times, merged.times[50:-50] + 1.0)
    assert np.median(np.abs(merged.acc[50:-50, 1] - together.acc[k, 1])) < 0.2


def test_sensors_recorded_apart_are_refused_by_name(tmp_path, pair_rec):
    shin = _unix_file(tmp_path / "shin.csv", pair_rec.select(["right_ankle"]), 0.0, 5.0)
    watch = _unix_file(tmp_path / "watch.csv", pair_rec.select(["left_wrist"]), 2.0, 9.0)
    with pytest.raises(FormatError, match=r"60 %.*right_ankle.*expected at least 80 %"):
        read_sensors(shin, [("left_wrist", watch)])
    check_overlap({"a": (0.0, 10.0), "b": (1.5, 9.5)}, {"a": "a.csv", "b": "b.csv"})  # 100 %
    with pytest.raises(FormatError, match="78 %.*b.csv"):
        check_overlap({"a": (0.0, 10.0), "b": (3.0, 12.0)}, {"a": "a.csv", "b": "b.csv"})


# ---- the model that reads them --------------------------------------------------------------
def test_the_model_reading_every_sensor_is_chosen(monkeypatch, tmp_path, pair_model,
                                                  ridge_without_demo_clip):
    import imuloco.data
    from imuloco.app import pipeline
    from imuloco.app.pipeline import choose_model, shipped_combination

    shutil.copy(pair_model, tmp_path / pair_model.name)
    ridge_without_demo_clip.save(tmp_path / "ridge_right_ankle.npz")
    monkeypatch.setattr(imuloco.data, "MODELS_DIR", tmp_path)
    monkeypatch.setattr(pipeline, "MODELS_DIR", tmp_path)  # where the pipeline looks it up
    assert shipped_combination("ridge", PAIR, "right_ankle") == tmp_path / pair_model.name
    assert shipped_combination("ridge", ["right_ankle", "left_ankle"], "right_ankle") is None
    both = choose_model("ridge", placement="right_ankle", available=PAIR)
    assert both.source == "shipped" and both.method.placements_ == PAIR
    one = choose_model("ridge", placement="right_ankle", available=["right_ankle"])
    assert one.method.placements_ == ["right_ankle"]


def test_the_fallback_reads_what_both_sensors_observe(pair_rec, pair_model):
    """A shin and a watch: the fallback's report says the legs and the arms are observed
    (the union of the two placements'), only the trunk left to guess."""
    from imuloco.app.pipeline import reconstruct_recording
    from imuloco.methods import load_model

    _, info = reconstruct_recording(pair_rec, load_model(pair_model))
    got = info["fallback"].to_json()
    assert got["enabled"] and got["observes"] == ["legs", "arms"]
    assert "(trunk)" in got["note"] and "right_ankle+left_wrist" in got["note"]


def test_an_ignored_sensor_is_warned_and_reported(tmp_path, pair_rec, ridge_without_demo_clip,
                                                  caplog):
    from imuloco.app.pipeline import reconstruct_file

    log = write_generic_csv(pair_rec, tmp_path / "pair.csv")
    with caplog.at_level(logging.WARNING, logger="imuloco.app.pipeline"):
        _, report = reconstruct_file(log, fitted=ridge_without_demo_clip)
    assert any("left_wrist are ignored" in r.getMessage() for r in caplog.records)
    assert [(s["placement"], s["used"]) for s in report["sensors"]] == [
        ("right_ankle", True), ("left_wrist", False)]


# ---- simulate -> reconstruct ----------------------------------------------------------------
def _cli(*args: str) -> None:
    res = CliRunner().invoke(cli, [str(a) for a in args])
    assert res.exit_code == 0, res.output


def test_simulated_export_with_watch_reconstructs_from_both(tmp_path, pair_model):
    from imuloco.app.pipeline import DEMO_CLIP
    from imuloco.data import SAMPLE_DIR

    bvh = SAMPLE_DIR / f"{DEMO_CLIP}.bvh"
    _cli("simulate", bvh, "--placement", "right_ankle,left_wrist", "--layout", "sensorlogger",
         "-o", tmp_path / "export")
    _cli("reconstruct", tmp_path / "export", "--model", pair_model, "-o", tmp_path / "a.bvh",
         "--report", tmp_path / "a.json")
    report = json.loads((tmp_path / "a.json").read_text())
    assert [(s["placement"], s["used"]) for s in report["sensors"]] == [
        ("right_ankle", True), ("left_wrist", True)]
    assert report["sensors"][1]["file"].endswith(WATCH_FILE)


def test_simulated_files_on_two_clocks_reconstruct_from_both(tmp_path, pair_model):
    from imuloco.app.pipeline import DEMO_CLIP
    from imuloco.data import SAMPLE_DIR

    bvh = SAMPLE_DIR / f"{DEMO_CLIP}.bvh"
    _cli("simulate", bvh, "--placement", "right_ankle,left_wrist", "--layout", "files",
         "--stomp", "--clock-offset", "left_wrist=1.5", "-o", tmp_path / "files")
    _cli("reconstruct", tmp_path / "files" / "right_ankle.csv", "--sensor",
         f"left_wrist={tmp_path / 'files' / 'left_wrist.csv'}", "--model", pair_model,
         "-o", tmp_path / "b.bvh", "--report", tmp_path / "b.json")
    report = json.loads((tmp_path / "b.json").read_text())
    wrist = report["sensors"][1]
    assert wrist["placement"] == "left_wrist" and wrist["used"]
    assert wrist["aligned_by"] == "xcorr" and abs(wrist["offset_s"] - 1.5) < FRAME_S


# ---- the path from every sensor of one kind -------------------------------------------------
def test_two_shins_give_one_path_from_both(walk):
    from imuloco.paths.registry import estimate_path

    rec = simulate(walk, ["right_ankle", "left_ankle", "left_wrist"], noise="phone", seed=0)
    right = estimate_path(rec.select(["right_ankle"]), "right_ankle")
    left = estimate_path(rec.select(["left_ankle"]), "left_ankle")
    both = estimate_path(rec, "right_ankle")  # the wrist has no path estimator: left out
    assert {f.foot for f in both.footfalls} == {"left", "right"}
    assert len(both.footfalls) == len(right.footfalls) + len(left.footfalls)
    mean = (right.root_xy + np.stack([np.interp(right.times_s, left.times_s, left.root_xy[:, k])
                                      for k in range(2)], 1)) / 2
    np.testing.assert_allclose(both.root_xy, mean, atol=1e-9)
    assert "right_ankle, left_ankle" in both.note


def test_two_feet_are_read_once_by_their_own_estimator(walk):
    pytest.importorskip("gaitmap")
    from imuloco.paths.foot import FootZupt
    from imuloco.paths.registry import estimate_path

    rec = simulate(walk, ["right_foot", "left_foot"], noise="phone", seed=0)
    both = estimate_path(rec, "right_foot")
    own = FootZupt().estimate(rec, "right_foot")  # it puts the pelvis between the feet itself
    assert len(both.footfalls) == len(own.footfalls)
    np.testing.assert_allclose(both.root_xy, own.root_xy, atol=1e-9)


# ---- the shipped shin + watch models --------------------------------------------------------
def _left_arm_cm(gt, rec) -> float:
    from imuloco.core.bodymap import resolve_body_map
    from imuloco.measures import metrics

    parts = resolve_body_map(gt.skeleton.names)
    cols = [gt.skeleton.names.index(parts[f"left_{p}"]) for p in ("elbow", "wrist")]
    err = metrics.joint_errors(gt, metrics.align_heading(rec, gt, 0))
    return float(err[:, cols].mean() * 100)


def test_the_shipped_shin_and_watch_model_is_chosen_and_reads_the_watch(walk, pair_rec):
    """A shin + watch recording gets the shipped pair model (and its mirror for the other
    side), and that model's left arm follows the watch: the same walk with the watch's signals
    two seconds late puts the left elbow and wrist further from the truth."""
    from dataclasses import replace

    from imuloco.app.pipeline import choose_model

    both = choose_model(placement="right_ankle", available=PAIR)
    assert both.source == "shipped" and both.method.placements_ == PAIR
    mirror = choose_model(placement="left_ankle", available=["left_ankle", "right_wrist"])
    assert mirror.method.placements_ == ["left_ankle", "right_wrist"]
    shift = 200  # 2 s at the simulation's 100 Hz
    late = replace(pair_rec, acc=pair_rec.acc.copy(), gyro=pair_rec.gyro.copy())
    for a in (late.acc, late.gyro):
        a[:, 1] = np.roll(a[:, 1], shift, axis=0)
    right = _left_arm_cm(walk, both.method.reconstruct(pair_rec))
    wrong = _left_arm_cm(walk, both.method.reconstruct(late))
    assert right < 0.8 * wrong, (right, wrong)
