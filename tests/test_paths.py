"""The body's path (issue 40): estimators on simulated walks, still recordings, the metrics."""

from __future__ import annotations

import numpy as np
import pytest

from imuloco.core.recording import Recording
from imuloco.paths.base import BodyPath, Footfall, strides_from_footfalls
from imuloco.paths.foot import FootZupt
from imuloco.paths.geometry import rotate, smooth_over
from imuloco.paths.metrics import mean_stride, path_errors, summarize, walked_distance
from imuloco.paths.registry import estimate_path, estimator_for
from imuloco.paths.shank import ShankPivot
from imuloco.paths.truth import path_of_motion
from imuloco.sensors.simulate import simulate


def _clip(sample_db, name):
    return next(m for m, lab in sample_db if lab["name"] == name)


def _still(placement: str, up_axis: int, seconds: float = 6.0) -> Recording:
    rng = np.random.default_rng(0)
    t = np.arange(int(seconds * 100)) / 100
    acc = np.zeros((len(t), 1, 3))
    acc[:, 0, up_axis] = 9.81
    acc += rng.normal(0, 0.02, acc.shape)
    return Recording(t, acc, rng.normal(0, 0.005, acc.shape), [placement])


@pytest.mark.parametrize("placement,up", [("right_ankle", 1), ("right_foot", 2)])
def test_a_still_recording_walks_nowhere(placement, up):
    path = estimate_path(_still(placement, up), placement, 1.7)
    assert path.distance_m() == pytest.approx(0.0, abs=1e-9)
    assert path.strides == [] and path.footfalls == []
    assert "no path" in path.note
    assert path.to_json()["distance_m"] == 0.0


@pytest.mark.parametrize("name", ["dataset-2_walk_active_001", "dataset-2_walk_feminine_001"])
def test_shank_path_walks_the_truths_distance(sample_db, name):
    """A shin phone (phone noise: jitter, biases, misplacement) on a straight walk: the
    distance and the mean stride within 6 % of the motion's own (measured: 0.5-1.3 % and
    1.1-2.9 %)."""
    motion = _clip(sample_db, name)
    rec = simulate(motion, ["right_ankle"], noise="phone", seed=0)
    path = ShankPivot().estimate(rec, "right_ankle", 1.7)
    err = path_errors(path, path_of_motion(motion))
    assert abs(err["distance_error_pct"]) < 6
    assert abs(err["stride_error_pct"]) < 6
    assert err["end_point_error_pct"] < 15
    assert path.heading_rad is not None and path.source == "shank-pivot"
    assert all(s.foot == "right" and 0 <= s.confidence <= 1 for s in path.strides)


def test_foot_path_walks_the_truths_distance(sample_db):
    """A shoe sensor on a straight walk: distance within 6 % (measured 0.1 % rts, 1.7 % mean
    anchored over the sample's walks)."""
    motion = _clip(sample_db, "dataset-2_walk_normal_001")
    rec = simulate(motion, ["right_foot"], noise="phone", seed=0)
    path = FootZupt().estimate(rec, "right_foot")
    err = path_errors(path, path_of_motion(motion))
    assert abs(err["distance_error_pct"]) < 6
    assert len(path.strides) >= 5


def test_truth_path_of_a_walk(sample_db):
    motion = _clip(sample_db, "dataset-2_walk_normal_001")
    path = path_of_motion(motion)
    assert path.root_xy[0] == pytest.approx([0.0, 0.0])
    # the walker sets off along the floor frame's x (its initial heading)
    assert path.root_xy[-1, 0] > 5 * abs(path.root_xy[-1, 1])
    assert {f.foot for f in path.footfalls} == {"left", "right"}
    assert 0.8 < mean_stride(path) < 2.0


def test_path_errors_of_the_truth_against_itself_and_turned(sample_db):
    truth = path_of_motion(_clip(sample_db, "dataset-2_walk-turn-left_normal_001"))
    same = path_errors(truth, truth)
    assert same["distance_ratio"] == pytest.approx(1.0)
    assert same["stride_error_m"] == pytest.approx(0.0)
    assert same["end_point_error_pct"] == pytest.approx(0.0, abs=1e-9)
    # an estimate in another yaw frame is turned to set off in the truth's direction
    turned = BodyPath(truth.times_s, rotate(truth.root_xy, 1.0), None, truth.footfalls,
                      truth.strides, "x", "")
    assert path_errors(turned, truth)["end_point_error_pct"] == pytest.approx(0.0, abs=1e-6)
    # a path 10 % too long reads +10 % on distance
    longer = BodyPath(truth.times_s, 1.1 * truth.root_xy, None, [], [], "x", "")
    assert path_errors(longer, truth)["distance_error_pct"] == pytest.approx(10.0, rel=1e-6)
    s = summarize([path_errors(longer, truth), same])
    assert s["distance_mae_pct"] == pytest.approx(5.0, rel=1e-6) and s["clips"] == 2


def test_distance_strides_and_json():
    t = np.linspace(0, 4, 401)
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    path = BodyPath(t[:4], square, None, [], [], "x", "")
    assert path.distance_m() == pytest.approx(3.0)
    falls = [Footfall("right", 0.0, np.zeros(2), 1.0), Footfall("right", 1.0, np.array([1.2, 0]),
                                                                0.5),
             Footfall("right", 9.0, np.array([5.0, 0]), 1.0)]  # 8 s later: a pause, no stride
    strides = strides_from_footfalls(falls)
    assert len(strides) == 1 and strides[0].length_m == pytest.approx(1.2)
    assert strides[0].speed_mps == pytest.approx(1.2) and strides[0].confidence == 0.5
    walk = BodyPath(t, np.stack([1.3 * t, 0 * t], 1), np.zeros(len(t)), falls, strides, "x", "n")
    j = walk.to_json()
    assert j["distance_m"] == pytest.approx(5.2) and j["strides"] == 1
    assert j["speed_mps"] == pytest.approx(1.3) and j["heading_known"]
    assert walked_distance(walk) == pytest.approx(5.2, rel=1e-3)


def test_smoothing_keeps_a_steady_walks_ends():
    """Averaged over a stride, a limb swinging about a steady walk is the walk, to its ends."""
    t = np.arange(600) / 100
    xy = np.stack([1.3 * t + 0.3 * np.sin(2 * np.pi * t), 0 * t], 1)
    mean = smooth_over(xy, 100, 1.0)
    assert mean[0, 0] == pytest.approx(0.0, abs=0.02)
    assert mean[-1, 0] == pytest.approx(1.3 * t[-1], abs=0.02)


def test_unknown_placement_is_named():
    from imuloco.errors import UnknownNameError

    with pytest.raises(UnknownNameError, match="no path estimator"):
        estimator_for("head")


def test_plot_path_writes_a_png(sample_db, tmp_path):
    pytest.importorskip("matplotlib")
    from imuloco.viz.plots import plot_path

    motion = _clip(sample_db, "dataset-2_walk-turn-left_normal_001")
    truth = path_of_motion(motion)
    est = ShankPivot().estimate(simulate(motion, ["right_ankle"], seed=0), "right_ankle", 1.7)
    out = plot_path(est, tmp_path / "path.png", truth)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_times_count_from_the_recordings_start(sample_db):
    motion = _clip(sample_db, "dataset-2_walk_active_001")
    rec = simulate(motion, ["right_ankle"], noise="clean", seed=0)
    late = Recording(rec.times + 100.0, rec.acc, rec.gyro, rec.placements)
    a, b = estimate_path(rec, "right_ankle", 1.7), estimate_path(late, "right_ankle", 1.7)
    assert b.times_s[0] == pytest.approx(0.0)
    assert [f.time_s for f in b.footfalls] == pytest.approx([f.time_s for f in a.footfalls])
    from imuloco.errors import UnknownNameError

    with pytest.raises(UnknownNameError, match="no sensor at"):
        estimate_path(rec, "left_ankle")


def test_gyro_integration_is_the_product_of_its_steps():
    """The prefix product equals the rotations composed one step after another (scipy)."""
    from scipy.spatial.transform import Rotation

    from imuloco.sensors.strapdown import integrate_gyro

    rng = np.random.default_rng(3)
    gyro = rng.normal(0, 3.0, (1001, 3))
    cur, want = Rotation.identity(), [Rotation.identity().as_quat()]
    for step in Rotation.from_rotvec(gyro[:-1] / 100.0):
        cur = cur * step
        want.append(cur.as_quat())
    got = integrate_gyro(gyro, 100.0)
    assert (got * Rotation.from_quat(want).inv()).magnitude().max() < 1e-12
