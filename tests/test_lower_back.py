"""Lower-back gait: the body axes found from the signal, Mobilise-D's pipeline on a simulated
L5 IMU worn in any axes, the protocol's bout coverage, and (marked ``shared``) the axes and
feet on real recordings."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from imuloco.core.recording import Recording
from imuloco.io.realimu import Bout, GaitDefinition, GaitReference, RealTrial, read_trials
from imuloco.lab.real import evaluate_gait, summarize
from imuloco.measures.sensorgait import SensorGait, chord_factor, stride_row

pytest.importorskip("mobgap")
from imuloco.measures.sensorgait import lower_back_gait
from imuloco.sensors.calibration import body_axes


@pytest.fixture(scope="module")
def walk(sample_db):
    """The demo walk and its simulated L5 IMU (sensor x left, y up, z forward)."""
    from imuloco.app.pipeline import DEMO_CLIP
    from imuloco.sensors.simulate import simulate

    clip = next(c for c in sample_db.clips if c.name == DEMO_CLIP)
    return clip, simulate(clip, ["lower_back"], rate=100.0, noise="clean", seed=0)


def pendulum_walk(forward_against_rise: bool = True, rate: float = 100.0) -> np.ndarray:
    """World acceleration (T, 3), x right, y forward, z up, +g up, of a trunk vaulting over
    each stance (1.8 steps/s): 2 cm up and down, the forward speed lowest at the top when
    ``forward_against_rise``; a smaller sideways sway at the stride's frequency."""
    t = np.arange(0, 20, 1 / rate)
    w = 2 * np.pi * 1.8
    up = 9.81 - 0.02 * w**2 * np.cos(w * t)  # height 0.02 cos(wt): highest at mid-stance
    fwd = 0.1 * w * np.sin(w * t) * (1 if forward_against_rise else -1)  # speed V - 0.1 cos
    side = 0.5 * np.sin(w / 2 * t)
    return np.stack([side, fwd, up], axis=1)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_body_axes_find_up_forward_and_right(seed):
    """In any sensor axes: up from gravity, forward as the direction whose acceleration runs
    against the rise (the pendulum), medio-lateral to the right (x up, z forward)."""
    rot = Rotation.random(random_state=seed).as_matrix()  # sensor axes in world axes
    acc = pendulum_walk() @ rot
    axes = body_axes(acc, 100.0)
    world = np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0]], float)  # up, right, forward
    assert np.allclose(axes, world @ rot, atol=1e-6)
    # a trunk speeding up while it rises would be walking backwards
    back = body_axes(pendulum_walk(forward_against_rise=False) @ rot, 100.0)
    assert np.allclose(back[2], -axes[2], atol=1e-6)
    assert np.allclose(back[1], -axes[1], atol=1e-6)


def test_simulated_l5_axes_and_feet(walk):
    """The simulated sensor's y is up and z forward; every stride's foot is the foot whose
    strike (from the clip's own motion) starts it."""
    from imuloco.phases import gait_phases

    demo_clip, l5 = walk
    axes = body_axes(l5.acc[:, 0], 100.0)
    assert axes[0] @ [0, 1, 0] > 0.95 and axes[2] @ [0, 0, 1] > 0.95
    g = lower_back_gait(l5.times, l5.acc[:, 0], l5.gyro[:, 0], 0.53 * 1.7)
    assert g.measured and len(g.strides) >= 10
    steps = gait_phases(demo_clip).steps
    strikes = sorted((f / demo_clip.fps, foot) for foot in ("left", "right")
                     for f in steps[foot])
    matched = [(s["foot"], foot) for s in g.strides for t, foot in
               [min(strikes, key=lambda x: abs(x[0] - s["start_s"]))]
               if abs(t - s["start_s"]) < 0.2]  # the clip's first strike is before its phases
    assert len(matched) >= len(g.strides) - 1
    assert all(ours == truth for ours, truth in matched)


def test_lower_back_gait_does_not_depend_on_how_the_sensor_is_worn(walk):
    l5 = walk[1]
    ref = lower_back_gait(l5.times, l5.acc[:, 0], l5.gyro[:, 0], 0.9)
    key = lambda g: [(r["foot"], r["start_s"], r["end_s"]) for r in g.strides]
    for seed in (4, 5):
        rot = Rotation.random(random_state=seed).as_matrix()
        g = lower_back_gait(l5.times, l5.acc[:, 0] @ rot.T, l5.gyro[:, 0] @ rot.T, 0.9)
        assert key(g) == key(ref)
        assert np.allclose([r["length_m"] for r in g.strides],
                           [r["length_m"] for r in ref.strides], rtol=1e-6)
        assert np.array_equal(g.initial_contacts, ref.initial_contacts)


@pytest.mark.parametrize("rate", [99.3, 51.2, 100.0 - 1e-13])
def test_lower_back_gait_runs_at_any_sampling_rate(walk, rate):
    """mobgap maps its per-second values onto the strides from half a second's samples
    rounded; where rounding goes up (99.3 or 51.2 Hz, or 100 Hz with float noise) its
    interpolation raised ValueError on a stride starting with its gait sequence."""
    l5 = walk[1]
    g = lower_back_gait(l5.times * 100.0 / rate, l5.acc[:, 0], l5.gyro[:, 0], 0.9)
    assert g.measured and len(g.strides) >= 10


def test_chord_factor_is_a_circle_s_chord_over_its_arc():
    r, turn = 3.0, np.radians([0.0, 20.0, 90.0, 180.0])
    chord = np.hypot(r * np.sin(turn), r - r * np.cos(turn))
    assert np.allclose(chord_factor(turn) * r * turn, chord)
    assert chord_factor(0.0) == 1.0 and np.isclose(chord_factor(np.pi / 2), 2 ** 1.5 / np.pi)


@pytest.mark.parametrize("name", ["dataset-2_walk-turn-left_exhausted_001",
                                  "dataset-2_walk-turn-right_exhausted_001"])
def test_turning_strides_are_the_chords_of_the_pelvis_s_path(sample_db, name):
    """On a turning walk each stride's length is the pendulum's times the chord factor of the
    angle the pelvis turned between its contacts, that of the motion capture's hip line (not
    the sensor's): up to 61 degrees in one stride here."""
    from imuloco.phases.events import heading_angle
    from imuloco.sensors.simulate import simulate

    clip = next(c for c in sample_db.clips if c.name == name)
    l5 = simulate(clip, ["lower_back"], rate=100.0, noise="clean", seed=0)
    rot = Rotation.random(random_state=3).as_matrix()  # worn in any axes
    args = (l5.times, l5.acc[:, 0] @ rot.T, l5.gyro[:, 0] @ rot.T, 0.9)
    chord, arc = lower_back_gait(*args), lower_back_gait(*args, chord=False)
    hips = clip.part_positions(["left_hip", "right_hip"])
    heading = heading_angle(hips[:, 0], hips[:, 1])
    at = lambda s: np.interp(s, np.arange(len(heading)) / clip.fps, heading)
    truth = [chord_factor(abs(at(s["end_s"]) - at(s["start_s"]))) for s in chord.strides]
    ratio = [c["length_m"] / a["length_m"] for c, a in zip(chord.strides, arc.strides)]
    assert len(ratio) >= 8 and min(ratio) < 0.975
    assert np.allclose(ratio, truth, atol=2e-3)


def test_bouts_without_an_estimated_stride_are_counted():
    """Errors average over the bouts the estimate measured; the share says how many. A
    reference of per-bout means counts the steps inside its bouts only (a contact between
    them is not one), one over the whole trial counts it."""
    rec = Recording(np.arange(0, 30, 0.01), np.zeros((3000, 1, 3)), np.zeros((3000, 1, 3)),
                    ["lower_back"])
    ics = np.arange(2.0, 8.0, 0.5)
    ref = GaitReference(initial_contacts={"any": np.concatenate([ics, ics + 18.0])},
                        bouts=[Bout(2.0, 7.5, cadence_spm=120, stride_length_m=1.2,
                                    speed_mps=1.2),
                               Bout(20.0, 25.5, cadence_spm=120, stride_length_m=1.2,
                                    speed_mps=1.2)], definition=GaitDefinition.BOUT_MEANS)
    gait = SensorGait("lower_back", "test", initial_contacts=np.append(ics, 14.0), strides=[
        stride_row("either", a, a + 1.0, 1.32, np.nan) for a in ics[:-2]])
    row = evaluate_gait(gait, RealTrial("mobilise-d-lab", "x", rec, ref), "test")
    assert (row["bouts_ref"], row["bouts_measured"]) == (2, 1)
    assert row["steps_est"] == len(ics)
    whole = replace(ref, definition=GaitDefinition.DISTANCE_OVER_STEPS)
    assert evaluate_gait(gait, RealTrial("x", "x", rec, whole), "test")["steps_est"] == len(ics) + 1
    assert row["stride_err_pct"] == pytest.approx(10.0)  # the measured bout only
    assert summarize([row])[0]["bouts_measured_pct"] == pytest.approx(50.0)


# ---- the real recordings ------------------------------------------------------------------
@pytest.mark.shared
def test_forward_is_the_mobilise_d_sensor_s_z(real_dir):
    """mobilise-d-lab's sensors are worn in Mobilise-D's axes (x up, y, z forward): the axes
    found from the signal alone agree in every recording (up within 37 degrees: the sensors
    lean up to 29 degrees; forward within 45 degrees, and never backwards)."""
    trials = list(read_trials(real_dir / "mobilise-d-lab", "mobilise-d-lab"))
    assert len(trials) == 7
    for tr in trials:
        axes = body_axes(tr.recording.acc[:, 0], 100.0)
        assert axes[0] @ [1, 0, 0] > 0.8, tr.name
        assert axes[2] @ [0, 0, 1] > 0.7, tr.name


@pytest.mark.shared
def test_feet_agree_with_ipol_gait_s_hand_checked_events(real_dir):
    """Ullrich's left/right on our axes (its model mirrors with the forward sign): each
    stride's foot is that of the reference contact that starts it."""
    agree = total = 0
    for tr in read_trials(real_dir / "ipol-gait", "ipol-gait", limit=3):
        k = tr.recording.placements.index("lower_back")
        g = lower_back_gait(tr.recording.times, tr.recording.acc[:, k],
                            tr.recording.gyro[:, k], 0.53 * tr.reference.height_m)
        ref = sorted((t, f) for f in ("left", "right") for t in tr.reference.initial_contacts[f])
        for s in g.strides:
            t, foot = min(ref, key=lambda x: abs(x[0] - s["start_s"]))
            if abs(t - s["start_s"]) < 0.25:
                total += 1
                agree += foot == s["foot"]
    assert total > 60 and agree / total > 0.9
