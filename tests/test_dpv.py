"""D_pv (Tautges et al. 2008 sec. 3.1) flags jitter that the joint-angle error D_E scores as
close (the paper's sec. 6.2 observation).

Not tested, because it does not hold: a half turn of the chest about the vertical (upper body
facing backwards) is nearly invisible to D_pv on this skeleton, since the chest's children
include the two shoulders, which swap places, and the sum over ordered child pairs (eq. 16)
is symmetric under that swap."""

from __future__ import annotations

import numpy as np

from imuloco.core.motion import Motion
from imuloco.measures.metrics import angle_error, dpv
from imuloco.ops.rotations import from_rotvec, qmul


def _offset(motion: Motion, joint: int, rotvec: np.ndarray) -> Motion:
    """motion with a rotation (T, 3) rotation vectors applied to one joint's local rotation."""
    rot = motion.rotations.copy()
    rot[:, joint] = qmul(rot[:, joint], from_rotvec(rotvec))
    return Motion(motion.skeleton, rot, motion.root.copy(), motion.fps, motion.name)


def test_dpv_flags_jitter_that_angle_error_scores_as_close(sample_db):
    gt = sample_db.where(content="walk", style="normal").clips[0].slice(0, 90)
    chest = gt.skeleton.part("chest")  # a joint with several children: D_pv sees it
    t = gt.num_frames
    delta = np.deg2rad(3.0)  # Cdot saturates at the bones' product (eq. 14): small jitter shows best
    steady = _offset(gt, chest, np.tile([delta, 0.0, 0.0], (t, 1)))
    sign = np.where(np.arange(t) % 2 == 0, 1.0, -1.0)[:, None]
    jitter = _offset(gt, chest, sign * [delta, 0.0, 0.0])
    # the same per-frame angle error, so D_E cannot tell them apart
    assert np.isclose(angle_error(gt, steady), angle_error(gt, jitter), rtol=1e-6)
    assert dpv(gt, jitter) > 2.0 * dpv(gt, steady)

