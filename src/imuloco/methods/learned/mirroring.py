"""``learned`` for the other leg: the weights reused, the other leg's signals mapped onto this
leg's sensor axes and the predicted pose mirrored back (:meth:`MirrorMixin.mirrored`)."""

from __future__ import annotations

from typing import Self

import numpy as np

from imuloco.core.mirror import mirror, mirror_frames, mirror_pairs, mirror_rotations
from imuloco.core.motion import Motion
from imuloco.methods.learned.model import CONTACT_PARTS
from imuloco.ops.rotations import from_6d, to_6d
from imuloco.sensors.simulate import simulate

HEADING_REFLECTION = np.diag([-1.0, 1.0, 1.0])  # left is +X in the heading frame
CONTACT_SWAP = [CONTACT_PARTS.index(p.replace("left", "#").replace("right", "left")
                                    .replace("#", "right")) for p in CONTACT_PARTS]


def _partner(placement: str) -> str:
    for a, b in (("left", "right"), ("right", "left")):
        if placement.startswith(a + "_"):
            return b + placement[len(a):]
    raise ValueError(f"placement {placement!r} has no left/right partner to mirror to")


class MirrorMixin:
    """The mirroring part of :class:`~imuloco.methods.learned.method.Learned`."""

    def _mirror_vectors(self, vectors: np.ndarray) -> np.ndarray:
        sk = self.skeleton_
        j = sk.num_joints
        rot = from_6d(vectors[..., : 6 * j].reshape(*vectors.shape[:-1], j, 6))
        rot = mirror_rotations(rot, self.frames_, mirror_pairs(sk), sk.parents,
                               HEADING_REFLECTION)
        out = vectors.copy()
        out[..., : 6 * j] = to_6d(rot).reshape(*vectors.shape[:-1], 6 * j)
        out[..., 6 * j + 1] *= -1  # leftward velocity
        out[..., 6 * j + 3] *= -1  # yaw rate
        return out

    def mirrored(self, motions: list[Motion]) -> Self:
        """This model for the mirror placements (``right_ankle`` -> ``left_ankle``).

        The other leg's sensor axes relate to this leg's mirrored ones by a signed permutation
        per sensor, found by simulating both on ``motions`` (clean) and mirroring one; the
        mirror frames of the skeleton come from ``motions`` too (:func:`mirror_frames`).
        """
        other = [_partner(p) for p in self.placements_]
        frames = mirror_frames(motions)
        c = self.channels_
        a, b = [], []
        for m in motions:
            rec_o = simulate(m, other, 100.0, "clean", 0)
            rec_s = simulate(mirror(m, frames), self.placements_, 100.0, "clean", 0)
            a.append(rec_o.channels())
            b.append(rec_s.channels())
        a, b = np.concatenate(a), np.concatenate(b)
        fit = np.linalg.lstsq(a, b, rcond=None)[0].T          # b ≈ a @ fit.T
        cmap = np.zeros((c, c))
        rows = np.argmax(np.abs(fit), axis=1)
        cmap[np.arange(c), rows] = np.sign(fit[np.arange(c), rows])
        new = type(self)(**self.get_params())
        new.set_setup(self.skeleton_, self.fps_, other, self.noise_)
        arrays, values = self.get_state()
        new.set_state(arrays, values)
        new.input_map_ = cmap @ self.input_map_
        new.output_mirror_ = not self.output_mirror_
        new.frames_ = frames
        # what the weights were trained on, and that this model reads them mirrored
        new.protocol_ = {**getattr(self, "protocol_", {}), "mirrored_from": self.placements_}
        return new
