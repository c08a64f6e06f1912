"""Foot pinning, offline (pin_feet) and online (FootPinner)."""

from __future__ import annotations

import numpy as np
import pytest

from imuloco.core.motion import Motion
from imuloco.measures.metrics import foot_skate, jitter
from imuloco.methods.postprocess import FootPinner, pin_feet
from imuloco.phases import foot_contacts

FEET = ("left_ankle", "right_ankle", "left_toe", "right_toe")  # heels pin the ankle joints


@pytest.fixture(scope="module")
def sliding(sample_db):
    """A walk whose root drifts sideways and wobbles (so the feet slide), and its contacts."""
    walk = sample_db.where(content="walk").clips[0]
    t = walk.times
    root = walk.root.copy()
    root[:, 0] += 0.3 * t + 0.02 * np.sin(2 * np.pi * 3.0 * t)
    drifted = Motion(walk.skeleton, walk.rotations, root, walk.fps, walk.name)
    c = foot_contacts(walk)
    parts = ("left_heel", "right_heel", "left_toe", "right_toe")
    return walk, drifted, np.stack([c[p] for p in parts], axis=1).astype(float)


def test_pinning_stops_the_sliding(sliding):
    walk, drifted, contacts = sliding
    pinned = pin_feet(drifted, contacts, FEET)
    truth = foot_contacts(walk)
    assert foot_skate(walk, drifted, truth) > 20.0
    assert foot_skate(walk, pinned, truth) < foot_skate(walk, walk, truth) + 1.0
    np.testing.assert_array_equal(pinned.root[:, 1], drifted.root[:, 1])  # heights untouched
    np.testing.assert_array_equal(pinned.rotations, drifted.rotations)


def test_smoothing_trades_sliding_for_jerk(sliding):
    walk, drifted, contacts = sliding
    truth = foot_contacts(walk)
    sharp = pin_feet(drifted, contacts, FEET)
    soft = pin_feet(drifted, contacts, FEET, smoothing=0.3)
    assert jitter(soft) < jitter(sharp)
    assert foot_skate(walk, sharp, truth) < foot_skate(walk, soft, truth) \
        < foot_skate(walk, drifted, truth)
    with pytest.raises(ValueError, match="smoothing"):
        pin_feet(drifted, contacts, FEET, smoothing=0.0)
    with pytest.raises(ValueError, match="smoothing"):
        FootPinner(1.5)


@pytest.mark.parametrize("smoothing", [1.0, 0.7])
def test_online_pinner_gives_the_offline_roots(sliding, smoothing):
    _, drifted, contacts = sliding
    rng = np.random.default_rng(0)
    soft = np.clip(contacts + rng.normal(0, 0.3, contacts.shape), 0, 1)  # probabilities
    offline = pin_feet(drifted, soft, FEET, smoothing)
    pos = drifted.positions()
    idx = [drifted.skeleton.part(f) for f in FEET]
    pinner = FootPinner(smoothing)
    online = np.stack([pinner.step(drifted.root[t], pos[t, idx] - drifted.root[t], soft[t])
                       for t in range(drifted.num_frames)])
    np.testing.assert_allclose(online, offline.root, atol=1e-9)


def _leg(m: Motion, side: str = "left") -> tuple[int, int, int]:
    return tuple(m.skeleton.part(f"{side}_{p}") for p in ("hip", "knee", "ankle"))


def test_two_bone_ik_puts_the_ankle_on_its_target(sliding):
    from imuloco.ops.ik import two_bone

    walk = sliding[0]
    glob, pos = walk.fk()
    hip, knee, ankle = chain = _leg(walk)
    parents = walk.skeleton.parents

    def bent(target: np.ndarray) -> Motion:
        rows = [parents[hip], hip, parents[knee], knee, parents[ankle], ankle]
        local = walk.rotations.copy()
        local[:, list(chain)] = two_bone(glob[:, rows], pos[:, list(chain)], target)
        return Motion(walk.skeleton, local, walk.root, walk.fps)

    target = pos[:, ankle] + [0.03, 0.02, -0.04]
    moved = bent(target)
    glob2, pos2 = moved.fk()
    np.testing.assert_allclose(pos2[:, ankle], target, atol=1e-6)
    np.testing.assert_allclose(pos2[:, hip], pos[:, hip], atol=1e-9)
    # the foot keeps its orientation, the rest of the body its pose
    np.testing.assert_allclose(np.abs(np.sum(glob2[:, ankle] * glob[:, ankle], -1)), 1.0,
                               atol=1e-9)
    other = [j for j in range(walk.skeleton.num_joints)
             if not _below(walk.skeleton.parents, j, hip)]
    np.testing.assert_allclose(pos2[:, other], pos[:, other], atol=1e-9)
    # a target beyond reach: the leg stretches towards it
    far = pos[:, hip] + 2.0 * (pos[:, ankle] - pos[:, hip])
    reach = bent(far).positions()
    length = (np.linalg.norm(pos[:, knee] - pos[:, hip], axis=-1)
              + np.linalg.norm(pos[:, ankle] - pos[:, knee], axis=-1))
    np.testing.assert_allclose(np.linalg.norm(reach[:, ankle] - pos[:, hip], axis=-1), length,
                               atol=1e-5)
    toward = (reach[:, ankle] - pos[:, hip]) / length[:, None]
    wanted = (far - pos[:, hip]) / np.linalg.norm(far - pos[:, hip], axis=-1, keepdims=True)
    np.testing.assert_allclose(toward, wanted, atol=1e-5)


def _below(parents: np.ndarray, j: int, top: int) -> bool:
    while j >= 0:
        if j == top:
            return True
        j = parents[j]
    return False


def _steps(m: Motion, joint: int) -> np.ndarray:
    """Horizontal distance a joint moves between frames (T - 1,)."""
    return np.linalg.norm(np.diff(m.positions()[:, joint][:, [0, 2]], axis=0), axis=-1)


def test_locking_holds_planted_feet_where_they_landed(sliding):
    from imuloco.methods.postprocess import lock_feet

    walk, _, contacts = sliding
    t = walk.times
    heel, toe = contacts[:, :2], contacts[:, 2:]
    root = walk.root.copy()
    root[:, 0] += 0.1 * t + 0.01 * np.sin(2 * np.pi * 3.0 * t)  # feet slide as the hips drift
    drifted = Motion(walk.skeleton, walk.rotations, root, walk.fps, walk.name)
    locked = lock_feet(drifted, heel, toe)
    for side, name in enumerate(("left", "right")):
        down = heel[:-1, side].astype(bool) & heel[1:, side].astype(bool)
        j = walk.skeleton.part(f"{name}_ankle")
        before, after = _steps(drifted, j)[down], _steps(locked, j)[down]
        assert before.mean() > 2e-3  # the drift: 3 mm a frame
        # held still, but where the heel lifts the hips have drifted out of the leg's reach
        assert np.median(after) < 1e-9 and np.mean(after < 1e-4) > 0.9
        assert after.mean() < 0.1 * before.mean()
    # hips swaying sideways: a heel is held exactly wherever the leg reaches, at the height
    # the motion gives it; a rolling toe (heel up) mostly lies beyond the stretched leg's
    # reach, and is held as far as it goes
    root = walk.root.copy()
    root[:, 0] += 0.005 * np.sin(2 * np.pi * 3.0 * t)
    swaying = Motion(walk.skeleton, walk.rotations, root, walk.fps, walk.name)
    locked = lock_feet(swaying, heel, toe)
    pos, raw = locked.positions(), swaying.positions()
    for side, name in enumerate(("left", "right")):
        hip, knee, ankle = _leg(walk, name)
        stretched = np.linalg.norm(pos[:, ankle] - pos[:, hip], axis=-1) > (
            np.linalg.norm(pos[:, knee] - pos[:, hip], axis=-1)
            + np.linalg.norm(pos[:, ankle] - pos[:, knee], axis=-1) - 1e-5)
        h, o = heel[:, side].astype(bool), toe[:, side].astype(bool)
        held = h[:-1] & h[1:] & ~stretched[1:]
        assert held.sum() > 10
        assert _steps(swaying, ankle)[held].mean() > 1e-3
        assert _steps(locked, ankle)[held].max() < 1e-6
        np.testing.assert_allclose(pos[~stretched, ankle, 1], raw[~stretched, ankle, 1],
                                   atol=1e-9)
        j = walk.skeleton.part(f"{name}_toe")
        roll = (o & ~h)[:-1] & (o & ~h)[1:]
        assert _steps(locked, j)[roll].mean() < _steps(swaying, j)[roll].mean()
    never = lock_feet(drifted, np.zeros_like(heel), np.zeros_like(toe))
    np.testing.assert_allclose(never.rotations, drifted.rotations, atol=1e-12)


def test_foot_lock_frame_by_frame_gives_the_offline_motion(sliding):
    from imuloco.methods.postprocess import FootLock, lock_feet

    _, drifted, contacts = sliding
    rng = np.random.default_rng(1)
    soft = np.clip(contacts + rng.normal(0, 0.3, contacts.shape), 0, 1)
    offline = lock_feet(drifted, soft[:, :2], soft[:, 2:], smoothing=0.7)
    pos = drifted.positions()
    lock = FootLock(drifted.skeleton, drifted.fps, 0.7)

    def step(i: int) -> np.ndarray:
        targets = lock.targets(pos[i, lock.feet], soft[i, :2], soft[i, 2:])
        return lock.bend(drifted.rotations[i:i + 1], drifted.root[i:i + 1], targets[None],
                         turns=lock.turn[None])

    online = np.concatenate([step(i) for i in range(drifted.num_frames)])
    np.testing.assert_allclose(online, offline.rotations, atol=1e-12)
    assert np.abs(offline.rotations - drifted.rotations).max() > 0.01  # it did bend legs
    with pytest.raises(ValueError, match="smoothing"):
        FootLock(drifted.skeleton, drifted.fps, 0.0)


def test_a_held_foot_slides_once_the_motion_leaves_it_a_foot_length_behind(sliding):
    from imuloco.methods.postprocess import MAX_HOLD_FEET, lock_feet

    drifted = sliding[1]  # the hips drift 0.3 m/s: a foot held down all along
    ones = np.ones((drifted.num_frames, 2))
    locked = lock_feet(drifted, ones, ones)
    sk = drifted.skeleton
    for name in ("left", "right"):
        a, t = sk.part(f"{name}_ankle"), sk.part(f"{name}_toe")
        foot = np.linalg.norm(sk.offsets[t])  # the sample rig's toe hangs off the ankle
        away = np.linalg.norm((locked.positions()[:, a] - drifted.positions()[:, a])[:, [0, 2]],
                              axis=-1)
        assert away.max() <= MAX_HOLD_FEET * foot + 1e-6
        assert away.max() > 0.9 * MAX_HOLD_FEET * foot  # it was held that far


def _turned_feet(walk: Motion, angle: np.ndarray) -> Motion:
    """``walk`` with both ankles turned by ``angle`` (T,) radians about their parents' y axes
    (the feet swing about the ankles, their toes sweeping the floor)."""
    from imuloco.ops.rotations import about_y, qmul

    local = walk.rotations.copy()
    for name in ("left", "right"):
        a = walk.skeleton.part(f"{name}_ankle")
        local[:, a] = qmul(about_y(angle), local[:, a])
    return Motion(walk.skeleton, local, walk.root, walk.fps, walk.name)


def _direction(m: Motion, name: str) -> np.ndarray:
    """Unit ankle-to-toe directions (T, 3) of one foot."""
    pos = m.positions()
    d = pos[:, m.skeleton.part(f"{name}_toe")] - pos[:, m.skeleton.part(f"{name}_ankle")]
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def test_a_flat_foot_neither_tilts_nor_turns(sliding):
    from imuloco.methods.postprocess import lock_feet

    walk, _, contacts = sliding
    heel, toe = contacts[:, :2], contacts[:, 2:]
    wobbly = _turned_feet(walk, 0.15 * np.sin(2 * np.pi * 2.0 * walk.times))
    held = lock_feet(wobbly, heel, toe)
    free = lock_feet(wobbly, heel, toe, hold_flat=False)
    for side, name in enumerate(("left", "right")):
        flat = (heel[:, side] > 0.5) & (toe[:, side] > 0.5)
        both = flat[:-1] & flat[1:]
        assert both.sum() > 20
        tip = walk.skeleton.part(f"{name}_toe")
        # without the hold the toe sweeps about the held ankle; with it, it stays too
        assert _steps(free, tip)[both].mean() > 3e-3
        assert np.median(_steps(held, tip)[both]) < 1e-9
        assert _steps(held, tip)[both].mean() < 0.1 * _steps(free, tip)[both].mean()
        # the direction held is the one the foot landed with (flat frames after the first)
        d = _direction(held, name)
        steady = np.flatnonzero(both) + 1
        np.testing.assert_allclose(np.sum(d[steady] * d[steady - 1], -1), 1.0, atol=1e-9)
        # off the floor the foot is the motion's again once the hold has faded (0.1 s a 1/e)
        lifted = ~np.convolve(flat, np.ones(20), "full")[:len(flat)].astype(bool)  # 0.67 s
        assert lifted.sum() > 10
        np.testing.assert_allclose(_direction(held, name)[lifted],
                                   _direction(wobbly, name)[lifted], atol=1e-3)


def test_a_flat_foot_turns_along_once_the_motion_turns_it_a_radian(sliding):
    from imuloco.methods.postprocess import MAX_HOLD_FEET, lock_feet

    walk = sliding[0]
    ones = np.ones((walk.num_frames, 2))  # both feet flat all along
    turning = _turned_feet(walk, 2.0 * walk.times / walk.times[-1])  # two radians in all
    locked = lock_feet(turning, ones, ones)
    for name in ("left", "right"):
        cos = np.sum(_direction(locked, name) * _direction(turning, name), -1)
        angle = np.arccos(np.clip(cos, -1.0, 1.0))
        assert angle.max() <= MAX_HOLD_FEET + 1e-6
        assert angle.max() > 0.5 * MAX_HOLD_FEET  # it was held that far


def test_the_turn_between_two_directions_is_the_shortest_rotation():
    from imuloco.methods.postprocess import _between
    from imuloco.ops.ik import arc
    from imuloco.ops.rotations import to_rotvec

    rng = np.random.default_rng(2)
    u, v = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    np.testing.assert_allclose(_between(u, v), to_rotvec(arc(u, v)), atol=1e-12)
    np.testing.assert_array_equal(_between(u, 2 * u), 0.0)


def _pitch(m: Motion, name: str) -> np.ndarray:
    d = _direction(m, name)
    return np.arctan2(d[:, 1], np.linalg.norm(d[:, [0, 2]], axis=-1))


def test_a_flat_foot_is_held_at_the_flat_pitch_with_the_heading_it_lands_with(sliding):
    from imuloco.methods.postprocess import lock_feet
    from imuloco.phases.contacts import flat_foot_pitch

    walk, _, contacts = sliding
    heel, toe = contacts[:, :2], contacts[:, 2:]
    pitch = flat_foot_pitch([walk])
    flat_l = (heel[:, 0] > 0.5) & (toe[:, 0] > 0.5)
    np.testing.assert_allclose(pitch, np.median(np.r_[
        _pitch(walk, "left")[flat_l],
        _pitch(walk, "right")[(heel[:, 1] > 0.5) & (toe[:, 1] > 0.5)]]))
    wobbly = _turned_feet(walk, 0.15 * np.sin(2 * np.pi * 2.0 * walk.times))
    target = pitch - 0.2  # a pitch no frame has: the hold sets it
    held = lock_feet(wobbly, heel, toe, flat_pitch=target)
    landing = lock_feet(wobbly, heel, toe)
    for side, name in enumerate(("left", "right")):
        flat = (heel[:, side] > 0.5) & (toe[:, side] > 0.5)
        np.testing.assert_allclose(_pitch(held, name)[flat], target, atol=1e-9)
        # the heading is the one the foot landed with, as without a flat pitch
        h = _direction(held, name)[flat][:, [0, 2]]
        g = _direction(landing, name)[flat][:, [0, 2]]
        cos = np.sum(h * g, -1) / np.linalg.norm(h, axis=-1) / np.linalg.norm(g, axis=-1)
        np.testing.assert_allclose(cos, 1.0, atol=1e-9)
        tip = walk.skeleton.part(f"{name}_toe")
        both = flat[:-1] & flat[1:]
        assert np.median(_steps(held, tip)[both]) < 1e-9
    assert flat_foot_pitch([walk.slice(0, 1)]) is None  # no flat foot: none to hold


def test_the_quaternion_of_a_rotation_vector():
    from imuloco.methods.postprocess import _quaternion
    from imuloco.ops.rotations import from_rotvec

    r = np.random.default_rng(3).normal(size=(50, 3))
    r[0] = 0.0
    np.testing.assert_allclose(_quaternion(r), from_rotvec(r), atol=1e-12)


def _lock_by_loop(motion: Motion, heel: np.ndarray, toe: np.ndarray, **kw) -> np.ndarray:
    """The reference: the foot lock run frame after frame (lock_feet's loop before it was
    compiled), its legs bent once at the end."""
    from imuloco.methods.postprocess import FootLock

    lock = FootLock(motion.skeleton, motion.fps, **kw)
    legs = lock.legs(motion.rotations, motion.root)
    targets, turns = [], []
    for f, h, o in zip(legs[1][:, lock.sub_feet], heel, toe):
        targets.append(lock.targets(f, h, o))
        turns.append(lock.turn.copy())
    return lock.bend(motion.rotations, motion.root, np.array(targets), legs, np.array(turns))


@pytest.mark.parametrize("engine", ["numba", "numpy"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_lock_feet_equals_the_frame_loop_on_random_motions(sample_db, engine, seed):
    """Random joint rotations, a wandering root and random contacts (flat feet, lone heels and
    toes, lifts, slides past the hold's bound): the compiled and the numpy lock give the
    frame loop's legs to rounding, with and without a flat pitch."""
    if engine == "numba":
        pytest.importorskip("numba")
    from imuloco.methods.postprocess import lock_feet
    from imuloco.ops.rotations import from_rotvec

    rng = np.random.default_rng(seed)
    sk = sample_db.clips[0].skeleton
    n = 400
    rot = from_rotvec(np.cumsum(rng.normal(0, 0.05, (n, sk.num_joints, 3)), axis=0) * 0.3)
    root = np.cumsum(rng.normal(0, 0.02, (n, 3)), axis=0) + [0.0, 0.9, 0.0]
    motion = Motion(sk, rot, root, 30.0)
    # runs of contact: states held for a few frames, probabilities around the threshold
    states = np.repeat(rng.random((n // 8 + 1, 4)), 8, axis=0)[:n]
    probs = np.clip(states + rng.normal(0, 0.1, states.shape), 0, 1)
    for kw in ({"smoothing": 0.7}, {"smoothing": 1.0, "flat_pitch": -0.1},
               {"smoothing": 0.5, "hold_flat": False, "release_s": 0.05}):
        want = _lock_by_loop(motion, probs[:, :2], probs[:, 2:], **kw)
        got = lock_feet(motion, probs[:, :2], probs[:, 2:], engine=engine, **kw)
        assert np.abs(want - motion.rotations).max() > 0.05  # legs were bent
        np.testing.assert_allclose(got.rotations, want, atol=1e-9)
    with pytest.raises(ValueError, match="engine"):
        lock_feet(motion, probs[:, :2], probs[:, 2:], engine="fortran")
