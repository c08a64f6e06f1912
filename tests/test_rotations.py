"""ops.rotations: the per-pair weighted slerp against scipy's key-framed Slerp."""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from imuloco.ops.rotations import slerp_toward


def test_slerp_toward_is_scipys_slerp_per_pair():
    rng = np.random.default_rng(3)
    a, b = Rotation.random(20, random_state=rng), Rotation.random(20, random_state=rng)
    w = rng.uniform(0, 1, 20)
    got = slerp_toward(a.as_quat(), b.as_quat(), w)
    want = np.stack([Slerp([0.0, 1.0], Rotation.concatenate([a[k], b[k]]))(w[k]).as_quat()
                     for k in range(20)])
    # same rotation (q and -q alike), and the ends are the inputs
    assert np.allclose(np.abs(np.sum(got * want, axis=-1)), 1.0, atol=1e-9)
    assert np.allclose(np.abs(np.sum(slerp_toward(a.as_quat(), b.as_quat(), 1.0) * b.as_quat(),
                                     axis=-1)), 1.0, atol=1e-9)
    assert np.allclose(slerp_toward(a.as_quat(), b.as_quat(), 0.0), a.as_quat(), atol=1e-12)
