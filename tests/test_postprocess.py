"""Foot pinning, offline (pin_feet) and online (FootPinner)."""

from __future__ import annotations

import numpy as np
import pytest

from imuloco.core.motion import Motion
from imuloco.evaluate.metrics import foot_skate, jitter
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
