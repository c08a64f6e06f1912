"""Gait from real sensors: readers of the real-data layouts, the sensor-level estimators on
simulated foot and lower-back IMUs, the protocol's matching and path alignment, and (marked
``shared``) the protocol on the real recordings."""

from __future__ import annotations

import json
import math
from itertools import pairwise

import numpy as np
import pytest

from imuloco.errors import FormatError
from imuloco.io.realimu import GaitDefinition, detect_layout, read_trials
from imuloco.lab.real import match_events, path_errors, reference_stance, run_real
from imuloco.measures.gait import gait_parameters

pytest.importorskip("gaitmap")
pytest.importorskip("mobgap")
from imuloco.measures.sensorgait import foot_gait, lower_back_gait, sensor_gait
from imuloco.sensors.foottrack import foot_track, slow_swings, swings

DEMO = "dataset-2_walk_normal_001"


@pytest.fixture(scope="module")
def demo_clip(sample_db):
    return next(c for c in sample_db.clips if c.name == DEMO)


@pytest.fixture(scope="module")
def demo_rec(demo_clip):
    from imuloco.sensors.simulate import simulate

    return simulate(demo_clip, ["right_foot", "left_foot", "lower_back"], rate=100.0,
                    noise="clean", seed=0)


def test_foot_placement_reads_gravity_on_the_instep_axis(demo_rec):
    """A flat foot's sensor (x left, y back to the heel, z dorsal) reads +g mostly on z and
    y (the Bandai rig's foot slopes from the high ankle joint to the toe joint), never on x."""
    acc = demo_rec.acc[:3, 0].mean(axis=0)
    assert np.linalg.norm(acc) == pytest.approx(9.81, abs=1.5)
    assert acc[2] > 5.0 and abs(acc[0]) < 2.0


def test_foot_gait_on_a_simulated_foot_imu(demo_rec, demo_clip):
    """The ZUPT strides of a simulated shoe IMU match the clip's own strides."""
    truth = gait_parameters(demo_clip)
    for k, foot in enumerate(("right", "left")):
        g = foot_gait(demo_rec.times, demo_rec.acc[:, k], demo_rec.gyro[:, k], foot)
        assert g.measured, g.reason
        s = g.summary()
        assert s["stride_length_m"] == pytest.approx(truth["stride_length_m"], rel=0.05)
        assert s["cadence_spm"] == pytest.approx(truth["cadence_spm"], rel=0.05)
        assert all(r["foot"] == foot and r["end_s"] > r["start_s"] for r in g.strides)


def test_a_foot_s_swings_end_at_its_contacts(demo_rec):
    """``swings_m[k]`` is the swing that ends at contact k: a stride's length is the swing
    ending at its last contact, and a window keeps the two aligned."""
    g = foot_gait(demo_rec.times, demo_rec.acc[:, 0], demo_rec.gyro[:, 0], "right")
    assert len(g.swings_m) == len(g.initial_contacts)
    by_end = dict(zip(g.initial_contacts.tolist(), g.swings_m.tolist(), strict=True))
    lengths = [(by_end[r["end_s"]], r["length_m"]) for r in g.strides
               if np.isfinite(r["length_m"])]
    assert len(lengths) >= 3
    np.testing.assert_allclose(*zip(*lengths, strict=True))
    w = g.window(g.initial_contacts[2], g.initial_contacts[-1])
    np.testing.assert_array_equal(w.swings_m, g.swings_m[2:])


def test_a_reconstruction_s_swings_end_at_its_strikes(demo_rec, demo_clip, monkeypatch):
    """The reconstruction baseline's ``swings_m`` (what ipol-gait's definition sums) is each
    strike's ankle distance from that foot's previous strike: a right stride's length is the
    swing ending at its last strike, and the swings sum to both ankles' floor distance."""
    from imuloco.io.realimu import GaitReference, RealTrial
    from imuloco.lab import real
    from imuloco.lab.real import reconstruction_gait
    from imuloco.phases import gait_phases

    # the reconstruction is the clip itself, so the swings can be read off the clip
    monkeypatch.setattr(real, "reconstruct_recording", lambda rec, fitted: (demo_clip, {}))
    fitted = type("Stub", (), {"name": "stub", "placements_": ["right_ankle"]})()
    trial = RealTrial("ipol-gait", "t", demo_rec, GaitReference(initial_contacts={}, bouts=[]))
    g = reconstruction_gait(trial, "right_foot", fitted)
    assert len(g.swings_m) == len(g.initial_contacts) >= 6
    by_end = dict(zip(np.round(g.initial_contacts - demo_rec.times[0], 4).tolist(),
                      g.swings_m.tolist(), strict=False))
    pairs = [(by_end[round(r["end_s"], 4)], r["length_m"]) for r in g.strides]
    assert len(pairs) >= 2
    np.testing.assert_allclose(*zip(*pairs, strict=True), atol=1e-3)
    steps = gait_phases(demo_clip).steps
    walked = 0.0
    for side in ("left", "right"):
        floor = demo_clip.part_positions([f"{side}_ankle"])[:, 0][:, [0, 2]]
        walked += np.linalg.norm(floor[steps[side][-1]] - floor[0]) if len(steps[side]) else 0
    assert g.swings_m.sum() == pytest.approx(walked, rel=0.05)


def test_a_foot_never_under_the_zupt_threshold_still_gets_its_strides(demo_rec, demo_clip):
    """Some walkers' feet never get under the ZUPT detector's 34 deg/s: a 60 deg/s tremor
    (25 Hz, 0.4 degrees) on the simulated shoe IMU keeps every 50 ms window above it, yet the
    stillest moment of each stance still stops the foot."""
    truth = gait_parameters(demo_clip)
    t = demo_rec.times
    gyro = demo_rec.gyro[:, 0] + np.radians(60.0) * np.sin(2 * np.pi * 25.0 * t)[:, None] * [
        1.0, 0.0, 0.0]
    g = foot_gait(t, demo_rec.acc[:, 0], gyro, "right")
    assert g.measured, g.reason
    s = g.summary()
    assert s["stride_length_m"] == pytest.approx(truth["stride_length_m"], rel=0.05)
    assert s["cadence_spm"] == pytest.approx(truth["cadence_spm"], rel=0.05)


def test_a_spike_at_toe_off_does_not_move_the_initial_contacts(demo_rec):
    """Some shoes ring at toe off: a 460 deg/s spike on the sagittal gyroscope just after
    the toe-off minimum, in the swing's direction, became Herzer's mid-swing peak and put the
    contact 0.3-0.5 s early (ipol-gait). The IC search reads the gyroscope low-passed."""
    t, acc, gyro = demo_rec.times, demo_rec.acc[:, 0], demo_rec.gyro[:, 0].copy()
    clean = foot_gait(t, acc, gyro, "right").initial_contacts
    sign = np.sign(np.median(gyro[np.linalg.norm(gyro, axis=1) > 3, 0]))  # the swing's way
    for s in foot_track(t, acc, gyro).starts:
        k = s + int(np.argmin(sign * gyro[s:s + 30, 0])) + 3
        gyro[k:k + 2, 0] += sign * 8.0
    spiked = foot_gait(t, acc, gyro, "right").initial_contacts
    assert len(spiked) == len(clean) >= 6
    assert np.abs(spiked - clean).max() < 0.1


def test_contacts_fall_back_to_the_unfiltered_gyroscope(demo_rec, monkeypatch):
    """Where the low-passed gyroscope shows no swing peak (a jogging stride's can blur into its
    toe off), the contact is searched on the unfiltered one: with a cutoff so low that no
    stride keeps its peak, every contact is still found."""
    from imuloco.measures import sensorgait

    t, acc, gyro = demo_rec.times, demo_rec.acc[:, 0], demo_rec.gyro[:, 0]
    walk = foot_gait(t, acc, gyro, "right").initial_contacts
    monkeypatch.setattr(sensorgait, "GYRO_CUTOFF_HZ", 0.3)
    g = foot_gait(t, acc, gyro, "right")
    assert g.measured and len(g.initial_contacts) == len(walk) >= 6
    assert np.abs(g.initial_contacts - walk).max() < 0.1


def test_a_running_foot_s_contacts_are_found_where_it_lands(sample_db):
    """A running foot lands later in its stride (counted from heel off) than Herzer's IC search
    reaches in a walking one (70 %): the search is stretched to the stance's stillest moment.
    On a simulated run the contacts fell 150-190 ms early; they are now within 30 ms."""
    from imuloco.phases import gait_phases
    from imuloco.sensors.simulate import simulate

    clip = next(c for c in sample_db.clips if c.name == "dataset-2_run_exhausted_001")
    rec = simulate(clip, ["right_foot"], rate=100.0, noise="clean", seed=0)
    g = foot_gait(rec.times, rec.acc[:, 0], rec.gyro[:, 0], "right")
    truth = np.asarray(gait_phases(clip).steps["right"]) / clip.fps
    errs, missed, extra = match_events(truth, g.initial_contacts)
    assert missed == extra == 0 and len(errs) >= 5
    assert np.abs(errs).max() < 0.03


def test_reference_stance_reads_the_foot_off_between_two_contacts():
    ic = np.array([0.0, 1.0, 2.0, 5.0])
    fc = np.array([0.6, 1.7, 4.0])  # the last stride (2 to 5 s, a pause) lies outside
    assert reference_stance(ic, fc, 0.0, 2.0) == pytest.approx(65.0)
    assert np.isnan(reference_stance(ic, fc, 3.0, 4.0))


def test_a_running_foot_s_brief_stances_still_separate_its_swings():
    """A running foot is under the swing threshold for tens of ms per stance (10-65 ms on
    pyshoe-vicon's jogging trial, in the 50 ms window maximum): 0.5 s swings at 400 deg/s,
    80 ms stances at 20 deg/s, and a 0.1 s push-off 70 ms before each swing. Both dips are
    about 25 ms in the window maximum; every swing is found, from its push-off on."""
    rate, stride, n = 200.0, 0.75, 12
    t = np.arange(0, n * stride + 1.0, 1 / rate)
    norm = np.full(len(t), 20.0)
    starts = []
    for k in range(n):
        s = 0.5 + k * stride
        starts.append(round(s * rate))
        norm[(t >= s) & (t < s + 0.1)] = 150.0  # push-off
        norm[(t >= s + 0.17) & (t < s + 0.67)] = 400.0  # swing, then an 80 ms stance
    found, moments = swings(np.stack([norm, 0 * norm, 0 * norm], axis=1), rate)
    assert len(found) == n
    assert np.abs(found - np.array(starts)).max() <= round(0.025 * rate)  # half a window early
    assert len(moments) == n + 1 and np.all(norm[moments[1:-1]] == 20.0)


def test_a_pivot_on_the_floor_is_no_swing():
    """Between two swings (pitch at 400 deg/s), a 0.4 s turn of the foot about the vertical at
    400 deg/s (a U-turn's pivot, the foot down) is part of the stance: 2 swings, one stance
    between them. The same turn about a horizontal axis is a third swing."""
    rate = 100.0
    t = np.arange(0, 4.0, 1 / rate)
    gyro = np.zeros((len(t), 3))
    for s in (0.5, 2.9):
        gyro[(t >= s) & (t < s + 0.4), 1] = 400.0  # swings: pitch
    turn = (t >= 1.7) & (t < 2.1)
    gyro[turn, 2] = 400.0  # a pivot: yaw
    found, moments = swings(gyro, rate)
    assert len(found) == 2 and len(moments) == 3
    assert 0.9 * rate < moments[1] < 2.9 * rate
    gyro[turn] = gyro[turn][:, [2, 1, 0]]  # the same turn about x
    assert len(swings(gyro, rate)[0]) == 3


def _slow_start_walk(rate: float, first_step_m: float) -> tuple[np.ndarray, np.ndarray, int]:
    """A gyroscope norm (deg/s, on x) and a path: 2 s standing, a first step of 0.4 s peaking
    at 120 deg/s (over the swing threshold for less than MIN_SWING_S), then 4 swings at
    400 deg/s with 0.4 s stances; the path moves ``first_step_m`` over the first step and
    1.2 m over each swing."""
    t = np.arange(0, 6.0, 1 / rate)
    norm = np.full(len(t), 5.0)
    path = np.zeros((len(t), 3))
    slow = (t >= 2.0) & (t < 2.4)
    norm[slow] = 120.0 * np.sin(np.pi * (t[slow] - 2.0) / 0.4)
    path[t >= 2.2, 0] = first_step_m
    for k in range(4):
        s = 2.8 + k * 0.8
        norm[(t >= s) & (t < s + 0.4)] = 400.0
        path[t >= s + 0.2, 0] = first_step_m + 1.2 * (k + 1)
    return np.stack([norm, 0 * norm, 0 * norm], axis=1), path, round(2.0 * rate)


@pytest.mark.parametrize("first_step_m, found", [(0.5, True), (0.05, False)])
def test_a_slow_first_step_counts_when_it_carries_the_foot(first_step_m, found):
    """A first step from standing too slow for the swing threshold is a swing when the ZUPT
    path carries the foot farther than the shortest stride (0.15 m) between the rests around
    it; a slow shuffle in place is not."""
    rate = 100.0
    gyro, path, step = _slow_start_walk(rate, first_step_m)
    fast, _ = swings(gyro, rate)
    starts, moments = slow_swings(gyro, rate, path)
    assert len(fast) == 4
    assert len(starts) == 4 + found and len(moments) == len(starts) + 1
    if found:
        assert abs(starts[0] - step) <= 2 and np.array_equal(starts[1:], fast)
        assert moments[0] < starts[0] < moments[1] < starts[1]


def test_the_zupt_detector_is_rts_kalman_s_default():
    """The ZUPTs or-ed with the stances' are the ones ``RtsKalman`` uses by default, which the
    slow steps' rests rely on (the module docstring says so)."""
    from gaitmap.trajectory_reconstruction import RtsKalman

    from imuloco.sensors.foottrack import _zupt_detector

    combo, _ = _zupt_detector(np.array([10, 50, 90]))
    norm = dict(combo.detectors)["norm"]
    assert norm.get_params() == RtsKalman().zupt_detector.get_params()


def test_cadence_leaves_pauses_out():
    """A walker who stops for 7 s between two walks of 1 s strides walks at 120 steps/min:
    an interval longer than the longest stride (3 s) is a pause, not a step."""
    from imuloco.measures.sensorgait import SensorGait

    ic = np.array([0.0, 1.0, 2.0, 3.0, 10.0, 11.0, 12.0])
    foot = SensorGait("right_foot", "", initial_contacts=ic, steps_per_contact=2)
    assert foot.summary()["cadence_spm"] == pytest.approx(120.0)
    assert foot.summary()["steps"] == 14
    back = SensorGait("lower_back", "", initial_contacts=np.array([0.0, 0.5, 1.0, 5.0, 5.5]))
    assert back.summary()["cadence_spm"] == pytest.approx(120.0)


def test_sensor_gait_is_consistent_by_construction(demo_rec):
    """speed = step length x cadence / 60 exactly, steps = 2 x contacts for a foot."""
    for placement in ("right_foot", "lower_back"):
        g = sensor_gait(demo_rec, placement, height_m=1.7)
        s = g.summary()
        assert s["speed_mps"] == pytest.approx(s["step_length_m"] * s["cadence_spm"] / 60)
        assert s["steps"] == g.steps_per_contact * len(g.initial_contacts)


def test_lower_back_gait_on_a_simulated_l5_imu(demo_rec, demo_clip):
    truth = gait_parameters(demo_clip)
    g = lower_back_gait(demo_rec.times, demo_rec.acc[:, 2], demo_rec.gyro[:, 2], 0.53 * 1.7)
    assert g.measured, g.reason
    assert g.summary()["cadence_spm"] == pytest.approx(truth["cadence_spm"], rel=0.05)


@pytest.mark.parametrize("seconds", [1.0, 30.0])
def test_no_walking_is_stated_not_zero(seconds):
    """Too short, or a sensor lying still: no gait, a reason, NaN rather than 0."""
    t = np.arange(0, seconds, 0.01)
    acc = np.tile([0.0, 0.0, 9.81], (len(t), 1)) + np.random.default_rng(0).normal(
        0, 0.02, (len(t), 3))
    gyro = np.random.default_rng(1).normal(0, 0.002, (len(t), 3))
    for g in (foot_gait(t, acc, gyro), lower_back_gait(t, acc, gyro, 0.9)):
        assert not g.measured and g.reason
        assert math.isnan(g.summary()["cadence_spm"]) and math.isnan(g.summary()["steps"])
        assert g.to_json()["reason"]


def test_lower_back_needs_a_height(demo_rec):
    with pytest.raises(ValueError, match="height"):
        sensor_gait(demo_rec, "lower_back")


def test_match_events_one_to_one():
    errs, missed, extra = match_events(np.array([1.0, 2.0, 3.0]),
                                       np.array([1.02, 1.05, 2.9, 5.0]))
    assert sorted(np.round(errs, 3)) == [-0.1, 0.02]
    assert (missed, extra) == (1, 2)


def test_ipol_stride_and_speed_follow_the_reference_s_definition():
    """ipol-gait spreads a bout's distance over all its steps (2 x distance / steps) and over
    its time from the first foot-off. A right foot whose swings cover exactly that distance,
    with exactly the reference's steps, must score no error, though its complete strides
    (without the short first swing from standing) average longer and its contacts' span is
    shorter than the bout. The walk's last contact comes 20 ms after the trial's end (its
    last strike) and still counts; a turning step just after the bout (within the matching
    tolerance) does not, nor a strike annotated after the trial's end. Read by the per-bout
    means' definition, the same reference gives the walk summary's error."""
    from dataclasses import replace

    from imuloco.io.realimu import Bout, GaitDefinition, GaitReference, RealTrial
    from imuloco.lab.real import evaluate_gait
    from imuloco.measures.sensorgait import SensorGait, stride_row

    right = np.array([0.5, 1.6, 2.7, 3.8, 4.9, 6.0])  # the reference's strikes, bout [0, 6]
    swings = np.array([0.4, 1.4, 1.4, 1.4, 1.4, 0.7, 0.9])  # the first from standing
    est = np.append(right + [0.01, 0.0, -0.01, 0.0, 0.01, 0.02], 6.2)  # then a turning step
    left = np.array([1.05, 2.15, 3.25, 4.35, 5.45, 5.95])
    dist, steps, end = float(swings[:6].sum()), 12, 6.0
    bout = Bout(0.0, end, dist, steps / 2, 60.0 * steps / end, 2 * dist / steps, dist / end)
    ref = GaitReference(initial_contacts={"right": np.append(right, 6.21), "left": left},
                        bouts=[bout], definition=GaitDefinition.DISTANCE_OVER_STEPS)
    strides = [stride_row("right", a, b, n, 0.6) for a, b, n in
               zip(est[:-1], est[1:], swings[1:], strict=True)]
    gait = SensorGait("right_foot", "test", strides=strides, initial_contacts=est,
                      steps_per_contact=2, swings_m=swings)
    row = evaluate_gait(gait, RealTrial("ipol-gait", "t", None, ref), "imuloco")
    assert row["stride_ref"] == pytest.approx(2 * 6.7 / 12)
    assert row["stride_err_pct"] == pytest.approx(0, abs=1e-9)
    assert row["speed_err_pct"] == pytest.approx(0, abs=1e-9)
    # the walk's summary (the complete strides in the window, the contacts' span) differs
    assert row["stride_mean_est"] == pytest.approx(np.mean(swings[1:]))
    assert row["stride_mean_err_pct"] > 5 and row["speed_mean_err_pct"] > 10
    means = evaluate_gait(gait, RealTrial("t", "t", None, replace(
        ref, definition=GaitDefinition.BOUT_MEANS)), "imuloco")
    assert means["stride_err_pct"] == pytest.approx(row["stride_mean_err_pct"])
    assert "stride_mean_err_pct" not in means  # what the README's note on them relies on
    # the strike annotated after the trial's end (6.21 s) counts in neither
    assert means["steps_ref"] == row["steps_ref"] == 12
    # a foot whose swings walked 5 % further is 5 % off in both
    gait.swings_m = swings * 1.05
    row = evaluate_gait(gait, RealTrial("ipol-gait", "t", None, ref), "imuloco")
    assert row["stride_err_pct"] == pytest.approx(5.0)
    assert row["speed_err_pct"] == pytest.approx(5.0)
    # both feet's strikes (a reconstruction's: one step each), the left's swings as long:
    # each foot walks the distance once, so the sum over both is twice it, and no error
    both = np.sort(np.concatenate([est[:-1], left]))
    side = np.isin(both, left)
    lswings = np.array([0.7, 1.4, 1.4, 1.4, 1.4, 0.4])
    sw = np.empty(len(both))
    sw[~side], sw[side] = swings[:6], lswings
    recon = SensorGait("right_foot", "test", strides=strides[:5], initial_contacts=both,
                       steps_per_contact=1, swings_m=sw)
    row = evaluate_gait(recon, RealTrial("ipol-gait", "t", None, ref), "reconstruction")
    assert row["stride_err_pct"] == pytest.approx(0, abs=1e-9)
    assert row["speed_err_pct"] == pytest.approx(0, abs=1e-9)


def test_strides_over_the_whole_trial_count_its_pauses(tmp_path):
    """pyshoe-vicon's reference (as its reader declares it) counts strides from foot flat to
    foot flat over the whole trial, a 2 s pause included: a foot with a contact before each
    foot flat and strides of the reference's length scores no cadence, speed or steps error,
    though the walk's summary (two contacts a stride over their span) gives 80 steps/min
    against the reference's 90."""
    from scipy.io import savemat

    from imuloco.lab.real import evaluate_gait
    from imuloco.measures.sensorgait import SensorGait, stride_row

    t = np.arange(1000) / 200.0
    imu = np.zeros((len(t), 6))
    imu[:, 2] = -9.81
    savemat(tmp_path / "a_LLIO.mat", {"imu_data": imu, "timestamps_all": t[None],
                                      "strideIndex": [[0, 200, 400, 800]],  # 0, 1, 2, 4 s
                                      "GCP": np.array([[0, 0], [1, 0], [2, 0], [3, 0]])})
    (trial,) = read_trials(tmp_path)
    ic = np.array([0.9, 1.9, 3.9])  # each just before its stride's foot flat
    gait = SensorGait("right_foot", "test", initial_contacts=ic, steps_per_contact=2,
                      strides=[stride_row("right", a, b, 1.0, 0.6) for a, b in pairwise(ic)])
    row = evaluate_gait(gait, trial, "imuloco")
    assert (row["steps_ref"], row["cadence_ref"], row["stride_ref"]) == (6, 90, 1)
    assert row["speed_ref"] == pytest.approx(0.75)
    for key in ("steps", "cadence", "stride", "speed"):
        assert row[f"{key}_err_pct"] == pytest.approx(0, abs=1e-9), key
    assert gait.summary()["cadence_spm"] == pytest.approx(80)


def test_the_note_on_the_strides_mean_names_the_rows_it_lists():
    """The README's sentence names the data sets and sensors of the rows with the strides'
    mean (whatever they are) and the definition they follow, and none of the others."""
    from imuloco.lab.real import MEAN_DEFINITION, _mean_note

    def s(ds, sensor, est="imuloco", mean=True):
        return {"dataset": ds, "sensor": sensor, "estimator": est} | (
            {"stride_mean_err_pct": 5.0, "speed_mean_err_pct": 6.0} if mean else {})

    assert _mean_note([s("pyshoe-vicon", "right_foot", mean=False)]) == ""
    note = _mean_note([s("ipol-gait", "right_foot"), s("ipol-gait", "right_foot", "recon"),
                       s("pyshoe-vicon", "right_foot", mean=False), s("ipol-gait", "left_foot"),
                       s("walk-10m", "lower_back")])
    assert note.startswith("ipol-gait's right_foot and left_foot; walk-10m's lower_back: ")
    assert f"({MEAN_DEFINITION.value})" in note and "pyshoe" not in note
    assert "walk-10m lower_back (imuloco) stride 5.0 %, speed 6.0 %." in note


def test_a_published_path_row_names_the_trial_s_sensor(tmp_path):
    """PyShoe's published path is that of the recording's one sensor, whatever its name."""
    from dataclasses import replace

    from scipy.io import savemat

    from imuloco.core.recording import Recording
    from imuloco.lab.real import published_path_row

    t = np.arange(400) / 200.0
    imu = np.zeros((len(t), 6))
    imu[:, 2] = -9.81
    path = np.stack([t, 0 * t], axis=1)
    savemat(tmp_path / "a_LLIO.mat", {"imu_data": imu, "timestamps_all": t[None],
                                      "strideIndex": [[0, 200, 399]], "pyshoeTrajectory": path,
                                      "GCP": path[[0, 200, 399]]})
    (trial,) = read_trials(tmp_path)
    assert published_path_row(trial)["sensor"] == "right_foot"
    rec = trial.recording
    left = replace(trial, recording=Recording(rec.times, rec.acc, rec.gyro, ["left_foot"]))
    row = published_path_row(left)
    assert row["sensor"] == "left_foot" and row["path_final_m"] == pytest.approx(0, abs=1e-9)
    both = Recording(rec.times, np.repeat(rec.acc, 2, axis=1), np.repeat(rec.gyro, 2, axis=1),
                     ["left_foot", "right_foot"])
    with pytest.raises(ValueError, match="pyshoe-vicon a: a published path needs a recording of one"):
        published_path_row(replace(trial, recording=both))


def test_path_errors_ignore_start_pose():
    """A path moved and turned on the floor has no error once its start is aligned."""
    ref = np.array([[0, 0], [1, 0], [2, 0.5], [2.5, 1.5], [2, 2.5]], float)
    a = 0.7
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    est = ref @ rot.T + [3.0, -1.0]
    t = np.arange(5.0)
    e = path_errors(t, est, t, ref)
    assert e["path_final_m"] == pytest.approx(0, abs=1e-9)
    e = path_errors(t, est * [1, -1], t, ref)  # mirrored: not a rigid motion
    assert e["path_mean_m"] > 0.1


def test_readers_on_generated_files(tmp_path):
    from scipy.io import savemat

    n = 400
    t = np.arange(n) / 200.0
    imu = np.zeros((n, 6))
    imu[:, 2] = -9.81
    savemat(tmp_path / "a_LLIO.mat", {"imu_data": imu, "timestamps_all": t[None],
                                      "gt": np.zeros((n, 2)), "strideIndex": [[10, 200, 390]],
                                      "GCP": np.array([[0, 0], [1, 0], [2, 0]])})
    assert detect_layout(tmp_path) == "pyshoe-vicon"
    (trial,) = read_trials(tmp_path)
    assert trial.recording.placements == ["right_foot"]
    assert trial.reference.bouts[0].distance_m == pytest.approx(2.0)
    assert trial.reference.stride_ends[1] == pytest.approx(1.0)
    assert trial.reference.definition is GaitDefinition.STRIDES_OVER_TRIAL

    ipol = tmp_path / "ipol"
    ipol.mkdir()
    (ipol / "1-1.json").write_text(json.dumps({
        "Height": 170, "TrialBoundaries": [10, 90], "UTurnBoundaries": [40, 50],
        "LeftFootEvents": [[12, 20], [60, 70]], "RightFootEvents": [[25, 35], [75, 85]]}))
    for key in ("lf", "rf", "lb"):
        rows = "\n".join("\t".join([str(i)] + ["0"] * 9) for i in range(100))
        (ipol / f"1-1_{key}.txt").write_text(
            "Acquisition frequency: 100 Hz\nPacketCounter\tAcc_X\tAcc_Y\tAcc_Z\tGyr_X\tGyr_Y"
            "\tGyr_Z\tMag_X\tMag_Y\tMag_Z\n" + rows + "\n")
    (trial,) = read_trials(ipol)
    assert trial.recording.placements == ["right_foot", "left_foot", "lower_back"]
    assert trial.reference.initial_contacts["left"].tolist() == [0.2, 0.7]
    assert trial.reference.height_m == pytest.approx(1.7)
    assert trial.reference.definition is GaitDefinition.DISTANCE_OVER_STEPS
    (ipol / "1-1_lb.txt").write_text("Acquisition rate 100\n")
    with pytest.raises(FormatError, match="1-1_lb.txt:1"):
        list(read_trials(ipol))


def _ipol_trial(folder, counters: dict[str, list[int]]) -> None:
    """An ipol-gait trial whose sensors' Gyr_X equals their PacketCounter."""
    folder.mkdir()
    (folder / "1-1.json").write_text(json.dumps({
        "Height": 170, "TrialBoundaries": [0, 9], "UTurnBoundaries": [3, 5],
        "LeftFootEvents": [[1, 2]], "RightFootEvents": [[6, 8]]}))
    for key, counter in counters.items():
        rows = "\n".join("\t".join([str(c), "0", "0", "9.81", str(c)] + ["0"] * 5)
                         for c in counter)
        (folder / f"1-1_{key}.txt").write_text(
            "Acquisition frequency: 100 Hz\nPacketCounter\tAcc_X\tAcc_Y\tAcc_Z\tGyr_X\tGyr_Y"
            "\tGyr_Z\tMag_X\tMag_Y\tMag_Z\n" + rows + "\n")


def test_ipol_samples_sit_at_their_packet_counter(tmp_path):
    """The wireless sensors drop packets (4 % of ipol-gait's, up to 12 % of a trial): each
    sample is placed at its PacketCounter, the time base of the reference events, and the
    three sensors are aligned on it, the dropped packets interpolated."""
    _ipol_trial(tmp_path / "a", {"rf": [0, 1, 2, 5, 6, 7, 8, 9, 10],
                                 "lf": [1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11],
                                 "lb": [0, 3, 3, 4, 9, 10]})  # a packet sent twice
    (trial,) = read_trials(tmp_path / "a")
    rec = trial.recording
    assert rec.times.tolist() == pytest.approx([c / 100 for c in range(1, 11)])
    # every sensor's Gyr_X (its counter) at the common times: interpolated over the gaps
    assert rec.gyro[:, :, 0] == pytest.approx(np.repeat(np.arange(1.0, 11)[:, None], 3, 1))
    _ipol_trial(tmp_path / "b", {"rf": [0, 1, 2], "lf": [0, 1, 2], "lb": [0, 2, 1]})
    with pytest.raises(FormatError, match="1-1_lb.txt:5: PacketCounter goes back"):
        list(read_trials(tmp_path / "b"))


def test_unknown_layout_is_named(tmp_path):
    with pytest.raises(FormatError, match="no real-data layout"):
        detect_layout(tmp_path)


# ---- the real recordings ------------------------------------------------------------------
@pytest.mark.shared
def test_real_protocol_on_one_trial_each(real_dir, tmp_path):
    rows = run_real(real_dir, tmp_path, limit=1)
    assert {r["dataset"] for r in rows} == {"pyshoe-vicon", "ipol-gait", "mobilise-d-lab"}
    for f in ("real.json", "real.csv", "README.md"):
        assert (tmp_path / f).is_file()
    ours = {(r["dataset"], r["sensor"]): r for r in rows if r["estimator"] == "imuloco"}
    shoe = ours[("pyshoe-vicon", "right_foot")]
    # one trial's figures (Vicon): every stride found, the path within 1 % of the distance
    assert shoe["steps_err_pct"] == 0
    # cadence as the reference counts it (strides over the trial): the steps' error
    assert shoe["cadence_err_pct"] == pytest.approx(shoe["steps_err_pct"], abs=1e-9)
    assert shoe["stride_mae_m"] < 0.10 and shoe["path_final_pct"] < 1.0
    assert abs(ours[("ipol-gait", "lower_back")]["cadence_err_pct"]) < 3
    # a foot's stance against ipol-gait's foot-off events: both near 60 % of the stride
    foot = ours[("ipol-gait", "right_foot")]
    assert 50 < foot["stance_ref"] < 70 and 50 < foot["stance_est"] < 70
    assert foot["stance_err_pp"] == pytest.approx(foot["stance_est"] - foot["stance_ref"])


# ---- heights, consistency and the report's gait --------------------------------------------
def test_running_lengths_agree_with_speed_and_cadence(sample_db):
    """speed = step length x cadence / 60 on running clips too (the flight is covered)."""
    for clip in sample_db.where(content="run").clips:
        g = gait_parameters(clip)
        assert g["speed_mps"] == pytest.approx(g["step_length_m"] * g["cadence_spm"] / 60)
        assert g["stride_length_m"] == pytest.approx(2 * g["step_length_m"])
        # the heel-to-heel separation at a strike misses the flight
        assert g["ankle_step_length_m"] < g["step_length_m"]


def test_to_height_scales_every_length_and_speed(demo_clip):
    from imuloco.measures.gait import stature, to_height
    from imuloco.measures.strides import stride_rows

    h = stature(demo_clip.skeleton)
    assert 1.4 < h < 2.0  # an adult's stature from the leg
    tall = to_height(demo_clip, 2.0)
    k = 2.0 / h
    assert stature(tall.skeleton) == pytest.approx(2.0)
    a, b = gait_parameters(demo_clip), gait_parameters(tall)
    for key in ("stride_length_m", "step_length_m", "speed_mps", "ankle_stride_length_m"):
        assert b[key] == pytest.approx(k * a[key], rel=1e-6)
    assert b["cadence_spm"] == pytest.approx(a["cadence_spm"])
    la = [r["length_m"] for r in stride_rows(demo_clip, digits=9)]
    lb = [r["length_m"] for r in stride_rows(tall, digits=9)]
    np.testing.assert_allclose(lb, k * np.asarray(la), rtol=1e-6)
    with pytest.raises(ValueError, match="metres"):
        to_height(demo_clip, 175.0)  # centimetres


def test_reconstruct_file_height_and_foot_gait(tmp_path, demo_rec, demo_clip):
    """A foot sensor: the report's gait comes from the sensor's signal (ZUPT strides), the
    motion from the shipped foot model, scaled to --height."""
    from imuloco.app.pipeline import choose_method, reconstruct_file
    from imuloco.io.sensorlog import write_generic_csv
    from imuloco.measures.gait import stature

    rec = demo_rec.select(["right_foot"])
    path = write_generic_csv(rec, tmp_path / "foot.csv")
    fitted, note = choose_method(placement="right_foot")
    assert "learned_right_foot.npz" in note and fitted.placements_ == ["right_foot"]
    motion, report = reconstruct_file(path, fitted=fitted, placement="right_foot",
                                      height=1.9)
    assert stature(motion.skeleton) == pytest.approx(1.9)
    assert report["height_m"] == 1.9
    assert report["calibration"][0]["up_from"] == "stances"
    assert "right_foot sensor" in report["gait_source"] and report["gait_note"] is None
    truth = gait_parameters(demo_clip)
    assert report["gait"]["stride_length_m"] == pytest.approx(truth["stride_length_m"],
                                                              rel=0.05)
    assert len(report["strides"]) >= 3 and report["strides"][0]["foot"] == "right"
    # no value of another source among the sensor's: the worn foot's stance is the sensor's,
    # what it does not measure is None, and the motion's own parameters stand beside them
    g, m = report["gait"], report.to_json()["motion_gait"]
    assert g["right_stance_pct"] == g["stance_pct"] and g["left_stance_pct"] is None
    assert g["cadence_rhythm_spm"] is None and g["duration_s"] == m["duration_s"]
    assert m["cadence_rhythm_spm"] == pytest.approx(truth["cadence_spm"], rel=0.1)
    json.dumps(report.to_json())


def test_a_shoe_sensor_in_its_makers_axes_reconstructs_as_one_in_the_foot_s(demo_rec):
    """Real shoe IMUs come in their own axes: calibrated, the foot model's motion is the one
    it gives for a sensor in the foot's frame; fed as it is, the model is lost."""
    from imuloco.app.pipeline import choose_method, reconstruct_recording
    from imuloco.core.recording import Recording
    from imuloco.measures.metrics import mpjpe
    from imuloco.ops.rotations import from_rotvec, qrot

    fitted, _ = choose_method(placement="left_foot")
    rec = demo_rec.select(["left_foot"])
    turn = from_rotvec(np.array([2.2, -0.4, 1.1]))  # a sensor lying on its side, turned
    turned = Recording(rec.times, qrot(turn, rec.acc), qrot(turn, rec.gyro), ["left_foot"])
    ref, _ = reconstruct_recording(rec, fitted, calibrate=False, pin=False)
    cal, info = reconstruct_recording(turned, fitted, pin=False)
    raw, _ = reconstruct_recording(turned, fitted, calibrate=False, pin=False)
    assert info["calibration"][0]["up_from"] == "stances"
    near, lost = mpjpe(ref, cal), mpjpe(ref, raw)  # cm
    assert near < 1.5 and lost > 4 * near, (near, lost)  # measured: 0.25 and 8.5 cm


def test_a_lower_back_sensor_uses_the_shipped_lower_back_model(tmp_path, demo_rec):
    """``reconstruct`` on a lower-back recording: the shipped lower-back model (no baseline
    fitted on the fly), the sensor calibrated from its own walk, the gait from its signal."""
    from imuloco.app.pipeline import choose_model, reconstruct_file
    from imuloco.core.recording import Recording
    from imuloco.io.sensorlog import write_generic_csv
    from imuloco.ops.rotations import from_rotvec, qrot

    choice = choose_model(placement="lower_back")
    assert choice.source == "shipped" and choice.path.name == "learned_lower_back.npz"
    assert choice.method.name == "learned" and choice.method.placements_ == ["lower_back"]
    rec = demo_rec.select(["lower_back"])
    turn = from_rotvec(np.array([0.3, 2.6, -0.9]))  # worn upside down and turned
    rec = Recording(rec.times, qrot(turn, rec.acc), qrot(turn, rec.gyro), ["lower_back"])
    motion, report = reconstruct_file(write_generic_csv(rec, tmp_path / "back.csv"),
                                      fitted=choice.method, placement="lower_back",
                                      height=1.7)
    assert report["calibration"][0]["up_from"] == "mean"
    assert "lower_back sensor" in report["gait_source"] and report["gait_note"] is None
    assert motion.num_frames == pytest.approx((rec.times[-1] - rec.times[0]) * 30, abs=2)


def test_a_lower_back_sensor_in_its_makers_axes_reconstructs_as_one_in_the_l5_frame(
        demo_rec, demo_clip):
    """As for the shoe: calibrated, the lower-back model's motion is near the one it gives
    for a sensor in the L5 frame (what is left is the calibration's few degrees); fed in the
    sensor's own axes, the model is lost."""
    from imuloco.app.pipeline import choose_method, reconstruct_recording
    from imuloco.core.recording import Recording
    from imuloco.measures.metrics import mpjpe
    from imuloco.ops.rotations import from_rotvec, qrot

    fitted, _ = choose_method(placement="lower_back")
    rec = demo_rec.select(["lower_back"])
    turn = from_rotvec(np.array([2.2, -0.4, 1.1]))
    turned = Recording(rec.times, qrot(turn, rec.acc), qrot(turn, rec.gyro), ["lower_back"])
    ref, _ = reconstruct_recording(rec, fitted, calibrate=False, pin=False)
    cal, _ = reconstruct_recording(turned, fitted, pin=False)
    raw, _ = reconstruct_recording(turned, fitted, calibrate=False, pin=False)
    near, lost = mpjpe(ref, cal), mpjpe(ref, raw)  # cm
    assert near < 1.5 and lost > 4 * near, (near, lost)  # measured: 0.25 and 14.3 cm


def test_a_model_refuses_a_placement_it_does_not_know(tmp_path, ridge_without_demo_clip):
    from imuloco.app.pipeline import choose_method

    model = ridge_without_demo_clip.save(tmp_path / "ankle.npz")
    with pytest.raises(ValueError, match="'right_foot'"):
        choose_method(model=model, placement="right_foot")


def test_gait_report_states_when_nothing_was_measured(demo_clip, demo_rec):
    from imuloco.measures.sensorgait import gait_report

    still = demo_clip.slice(0, 1)
    still = type(still)(still.skeleton, np.repeat(still.rotations, 60, axis=0),
                        np.repeat(still.root, 60, axis=0), still.fps)
    out = gait_report(still, demo_rec, "right_ankle").to_json()
    assert out["gait_note"].startswith("no gait could be measured")
    assert out["gait"]["cadence_spm"] is None and out["gait"]["steps"] is None


def test_the_summary_counts_the_contacts_no_estimate_matched():
    """Two recordings: one matched everywhere, one whose 8 contacts all came too early. The
    median timing error sees only the first; the matched share shows the second."""
    from imuloco.lab.real import summarize, table

    rows = [{"dataset": "d", "sensor": "right_foot", "estimator": "imuloco", "measured": True,
             "ic_matched": 12, "ic_missed": 0, "ic_median_ms": 10.0},
            {"dataset": "d", "sensor": "right_foot", "estimator": "imuloco", "measured": True,
             "ic_matched": 0, "ic_missed": 8, "ic_median_ms": math.nan}]
    s = summarize(rows)[0]
    assert s["ic_median_ms"] == 10.0
    assert s["ic_matched_pct"] == pytest.approx(60.0)
    assert "IC matched %" in table([s]) and "| 60.0 |" in table([s])


@pytest.mark.shared
def test_a_failing_estimator_is_logged_not_passed_off_as_no_gait(real_dir, monkeypatch,
                                                                 caplog):
    from imuloco.lab import real

    def broken(rec, placement, **kw):
        raise ValueError("the estimator broke")

    monkeypatch.setattr(real, "sensor_gait", broken)
    with caplog.at_level("WARNING", logger="imuloco.lab.real"):
        rows = run_real(real_dir / "ipol-gait", None, limit=1)
    assert rows and all(not r["measured"] and r["reason"] == "the estimator broke"
                        for r in rows if r["estimator"] == "imuloco")
    said = [m for m in caplog.messages if "the estimator broke" in m]
    assert len(said) == len([r for r in rows if r["estimator"] == "imuloco"])
    assert all(m.startswith("ipol-gait ") for m in said)
