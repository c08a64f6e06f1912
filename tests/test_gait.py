"""Cadence from a motion's rhythm (imuloco.measures.gait.motion_cadence)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from imuloco.core.motion import Motion
from imuloco.measures.gait import motion_cadence
from imuloco.ops.rotations import qmul
from imuloco.phases import gait_phases


@pytest.mark.parametrize("name", ["dataset-2_walk_active_001",
                                  "dataset-2_walk-turn-left_active_001",
                                  "dataset-2_walk_normal_001"])
def test_rhythm_cadence_matches_the_strikes(sample_db, name):
    """The ankles' alternation is nearly sinusoidal (no second harmonic): a two-harmonic
    score tied with the subharmonic and halved the cadence of these clips (61 and 69 for
    119 and 127 steps/min)."""
    clip = next(c for c in sample_db.clips if c.name == name)
    assert motion_cadence(clip) == pytest.approx(gait_phases(clip).cadence_spm, rel=0.05)


def test_rhythm_cadence_of_a_pure_alternation(sample_db):
    """Legs swinging as a pure sine at 1 stride/s for 6 s walk at 120 steps/min, whatever
    the clip length's frequency grid."""
    clip = next(c for c in sample_db.clips if c.name == "dataset-2_walk_normal_001")
    sk = clip.skeleton
    hips = [sk.part("left_hip"), sk.part("right_hip")]
    t = np.arange(int(6.1 * clip.fps)) / clip.fps
    rot = np.tile(clip.rotations[:1], (len(t), 1, 1))
    swing = 0.4 * np.sin(2 * np.pi * 1.0 * t)  # rad about the hip line, opposite legs
    for hip, sign in zip(hips, (1.0, -1.0)):
        # hip flexion about the skeleton's left-right axis: the hip line in the rest pose
        axis = sk.offsets[hips[1]] - sk.offsets[hips[0]]
        axis = axis / np.linalg.norm(axis)
        half = 0.5 * sign * swing[:, None]
        q = np.concatenate([np.sin(half) * axis, np.cos(half)], axis=-1)
        rot[:, hip] = qmul(q, rot[:, hip])
    root = np.tile(clip.root[:1], (len(t), 1))
    motion = Motion(sk, rot, root, clip.fps, "pure alternation")
    cadence = motion_cadence(motion)
    assert not math.isnan(cadence)
    assert cadence == pytest.approx(120.0, abs=2.0)
