"""The path, causally (imuloco.paths.live): strides read as their end footfall is detected, and
a live root that follows them without jumps."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from imuloco.app.live.session import LiveSession
from imuloco.core.recording import Recording
from imuloco.paths.base import BodyPath, Stride
from imuloco.paths.live import MAX_CORRECTION_MPS, RootFollower, StrideStream
from imuloco.paths.metrics import walked_distance
from imuloco.paths.registry import estimate_path
from imuloco.sensors.simulate import simulate

FPS = 30.0
# No jump: a live root's step in one frame is the model's own times the gain plus a
# correction's smoothstep, at most 1.5 MAX_CORRECTION_MPS / FPS = 2.5 cm; with gains within
# 1.3, at most 3 cm longer than the model's own step (0.9 m/s faster).
MAX_EXCESS_M = 0.03


def floor_distance(root: np.ndarray, fps: float = FPS) -> float:
    """walked_distance (imuloco.paths.metrics) of a root (T, 3)'s floor path."""
    xy = root[:, [2, 0]]
    return walked_distance(BodyPath(np.arange(len(xy)) / fps, xy, None, [], [], "", ""))


def test_the_root_follows_strides_read_late_without_jumps():
    """A model walking 1.0 m/s (swaying 3 cm side to side) while the path's strides say
    1.3 m per 1.1 s, each read 0.8 s after it ended: the followed root ends where the strides
    and the last one's pace put it, and no frame jumps."""
    t = np.arange(0, 20.0, 1 / FPS)
    model = np.stack([1.0 * t, 0.03 * np.sin(2 * np.pi * t / 1.1)], axis=1)
    ends = np.arange(1.1, 20.0, 1.1)
    f = RootFollower(FPS)
    out, k = [], 0
    for ti, xz in zip(t, model):
        while k < len(ends) and ends[k] + 0.8 <= ti:
            f.add(Stride("right", ends[k] - 1.1, ends[k], 1.3, 1.3 / 1.1, 1.0))
            k += 1
        out.append(f.step(ti, xz))
    out = np.array(out)
    forward = out[-1, 0]
    assert forward == pytest.approx(1.3 / 1.1 * t[-1], rel=0.01)  # the model's own: 20 m
    steps = np.linalg.norm(np.diff(out, axis=0), axis=1)
    own = np.linalg.norm(np.diff(model, axis=0), axis=1).max()
    assert steps.max() <= 1.3 / 1.1 * own + 1.5 * MAX_CORRECTION_MPS / FPS + 1e-9
    # a stride as long as the model's own displacement over it: the root stays the model's
    same = RootFollower(FPS)
    a, b = np.searchsorted(t, [1.0, 2.1])
    for i, (ti, xz) in enumerate(zip(t, model)):
        if i == round(3.0 * FPS):
            same.add(Stride("right", 1.0, 2.1, float(np.linalg.norm(model[b] - model[a])),
                            1.0, 1.0))
        np.testing.assert_allclose(same.step(ti, xz), xz, atol=1e-9)


@pytest.fixture(scope="module")
def shin_walk(sample_db):
    clip = next(c for c in sample_db.clips if c.name == "dataset-2_walk_normal_001")
    return simulate(clip, ["right_ankle"], 100.0, "phone", 3)


def test_strides_are_read_once_after_their_end_as_the_offline_estimator_finds_them(shin_walk):
    rec = shin_walk
    s = StrideStream("right_ankle")
    for i in range(len(rec.times)):
        s.push(rec.times[i], rec.acc[i, 0], rec.gyro[i, 0])
        s.poll()
    read = list(s.read)
    offline = [x for x in estimate_path(rec, "right_ankle").strides]
    assert len(read) >= len(offline) - 2 >= 4  # all but the last, not yet settled
    for stride, at in read:
        assert at >= stride.end_s + s.settle_s  # causal: read after its end had settled
        twin = min(offline, key=lambda o: abs(o.end_s + rec.times[0] - stride.end_s))
        assert abs(twin.end_s + rec.times[0] - stride.end_s) < 0.05
        assert stride.length_m == pytest.approx(twin.length_m, rel=0.03)
    ends = [x.end_s for x, _ in read]
    assert ends == sorted(ends) and len(set(ends)) == len(ends)


def _steps(root: np.ndarray) -> np.ndarray:
    """The floor distance (T-1,) a root (T, 3) moves from one frame to the next."""
    return np.linalg.norm(np.diff(root[:, [0, 2]], axis=0), axis=1)


def _live(method, rec: Recording, follow: bool = True) -> tuple[np.ndarray, LiveSession]:
    s = LiveSession(method, 4.0, follow_path=follow, fallback=False)  # the follower alone
    frames = [f for i in range(len(rec.times)) for f in s.push(rec.times[i], rec.acc[i],
                                                                 rec.gyro[i])]
    return np.stack([f.root for f in frames]), s


def test_the_live_root_covers_the_strides_it_read_and_never_jumps(ridge_without_demo_clip,
                                                                   shin_walk):
    live, s = _live(ridge_without_demo_clip, shin_walk)
    own, _ = _live(ridge_without_demo_clip, shin_walk, follow=False)
    read = [x for x, _ in s.strides.read]
    t = shin_walk.times[0] + np.arange(len(live)) / FPS
    a, b = np.searchsorted(t, [read[0].start_s, read[-1].end_s])
    covered = floor_distance(live[a:b + 1])
    assert covered == pytest.approx(sum(x.length_m for x in read), rel=0.05)
    assert abs(floor_distance(own[a:b + 1]) / covered - 1) > 0.05  # a real change
    assert (_steps(live) - _steps(own)).max() <= MAX_EXCESS_M
    np.testing.assert_allclose(live[:, 1], own[:, 1])  # the height is the model's


@pytest.mark.shared
def test_on_a_real_walk_the_live_distance_is_the_offline_paths(ridge_without_demo_clip):
    """60 s of the real shin walk (../shared realworld-shin) streamed: the live root's distance
    within 5 % of the offline path's (the shank-pivot estimate of the whole recording)."""
    from imuloco.sensors.reallog import read_log

    log = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "realworld-shin"
    if not log.is_dir():
        pytest.skip("../shared/data/realworld-shin is absent")
    rec, _ = read_log(log / "acc_walking_shin.csv", placement="right_ankle")
    k = (rec.times > rec.times[0] + 10) & (rec.times < rec.times[0] + 70)  # no gap in it
    rec = Recording(rec.times[k], rec.acc[k], rec.gyro[k], list(rec.placements))
    live, _ = _live(ridge_without_demo_clip, rec)
    own, _ = _live(ridge_without_demo_clip, rec, follow=False)
    path = estimate_path(rec, "right_ankle")
    assert floor_distance(live) == pytest.approx(walked_distance(path), rel=0.05)
    assert (_steps(live) - _steps(own)).max() <= MAX_EXCESS_M
