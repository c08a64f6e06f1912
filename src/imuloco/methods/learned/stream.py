"""``learned``'s online mode: :class:`LearnedStream` (one sensor frame in, one pose out) and
the foot pinning and locking both modes apply to the predicted contacts (:func:`pin`,
:func:`lock`)."""

from __future__ import annotations

from collections import deque
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np
import torch

from imuloco.core.motion import Motion
from imuloco.methods import pose
from imuloco.methods.base import Stream
from imuloco.methods.features import PoseIntegrator
from imuloco.methods.learned.model import CONTACT_PARTS
from imuloco.methods.postprocess import FootLock, FootPinner, lock_feet, pin_feet
from imuloco.ops.kinematics import joint_positions

if TYPE_CHECKING:
    from imuloco.methods.learned.method import Learned, Prediction

PIN_PARTS = CONTACT_PARTS  # heel contact pins the ankle joint, toe contact the toe joint
# Pinning corrections smoothed over a few frames (pin_feet's ``smoothing``): on 20 "exhausted"
# clips (phone noise, test seeds; the shipped model saw these motions in training) its jitter
# fell from 221 to 198 m/s^3 while foot skate rose from 9.9 to 11.4 cm/s (ground truth: 172
# and 10.7; unpinned: 187 and 24.6; smoothing 0.5: 190 and 13.5).
PIN_SMOOTHING = 0.7


def pin(motion: Motion, contacts: np.ndarray) -> Motion:
    """:func:`imuloco.methods.postprocess.pin_feet` with the predicted heel and toe contacts."""
    return pin_feet(motion, contacts, PIN_PARTS, PIN_SMOOTHING)


def lock(motion: Motion, contacts: np.ndarray, flat_pitch: float | None = None) -> Motion:
    """:func:`imuloco.methods.postprocess.lock_feet` with the predicted heel and toe contacts
    (:data:`CONTACT_PARTS` order: left and right heel, then toe), smoothed as the root's
    pinning is; a flat foot held at ``flat_pitch`` (a model's ``flat_pitch_``, the
    :func:`imuloco.phases.contacts.flat_foot_pitch` of the motions it learned from; None
    in files from before it: the pitch the foot lands with)."""
    return lock_feet(motion, contacts[:, :2], contacts[:, 2:], PIN_SMOOTHING,
                     flat_pitch=flat_pitch)


class LearnedStream(Stream):
    """One frame in, one pose out: the GRU state, the pose integrator and the foot pinning
    carried from frame to frame (bounded state), giving :meth:`Learned.reconstruct_signals`'s
    frames ``delay_frames`` steps late (the model's ``lag``, then the radius of its
    :attr:`Learned.height_weights`: a frame's height waits for its window); the steps before
    that return the model's mean pose at the origin. After each step, ``contacts`` (4,) and
    ``sigma`` (metres) hold the returned frame's contact probabilities and confidence."""

    def __init__(self, model: Learned) -> None:
        self.model = model
        self.weights = model.height_weights
        radius = len(self.weights) // 2
        self.delay_frames = model.lookahead + radius
        self.heights: deque[float] = deque(maxlen=2 * radius + 1)  # the root's, raw
        self.waiting: deque[Prediction] = deque(maxlen=radius + 1)  # the window's centre on
        self.height_index = pose.height_index(model.skeleton_)
        self.seen = 0
        mean = model.y_mean_[None]
        self.rest = PoseIntegrator(model.skeleton_, model.fps_).step(
            (model._mirror_vectors(mean) if model.output_mirror_ else mean)[0])
        self.h = model.net_.initial_state(1)
        self.integrator = PoseIntegrator(model.skeleton_, model.fps_)
        self.feet = [model.skeleton_.part(p) for p in PIN_PARTS]
        self.pinner = FootPinner(PIN_SMOOTHING)
        self.lock = FootLock(model.skeleton_, model.fps_, PIN_SMOOTHING,
                             flat_pitch=model.flat_pitch_)
        if self.feet != self.lock.feet:  # step() hands the pinned feet to the lock as they are
            raise ValueError(f"the foot lock reads joints {self.lock.feet}, pinning {self.feet}")
        self.contacts = np.zeros(len(PIN_PARTS))
        self.sigma = float("nan")
        self.novelty: float | None = None  # the smoothed novelty of the last frame read

    def step(self, sample: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        m = self.model
        with torch.inference_mode():
            x = m._inputs(np.asarray(sample)[None])
            feats, self.h = m.net_.encode(x[None], self.h)
            p, logit, logvar, members = m._heads(feats)
        nov = m._novelty(feats[0].numpy().astype(np.float64), self.novelty)
        self.novelty = float(nov[-1])
        self.seen += 1
        if self.seen <= m.lookahead:  # frame 0 is not read yet
            return self.rest[0].copy(), self.rest[1].copy()
        # the novelty of the frame read, not of the (delayed) frame returned: it lags the
        # offline result's by the look-ahead, within the smoothing's time constant
        out = m._outputs(p[0], logit[0], logvar[0], nov, None if members is None else members[0])
        h = self.height_index
        if not self.heights:  # frames before the first are the first (window_average's edge)
            self.heights.extend([out.vectors[0, h]] * (self.heights.maxlen // 2))
        self.heights.append(out.vectors[0, h])
        self.waiting.append(out)
        if len(self.heights) < self.heights.maxlen:  # frame 0's window is not read yet
            return self.rest[0].copy(), self.rest[1].copy()
        out = self.waiting[0]
        vectors = out.vectors.copy()
        vectors[0, h] = np.dot(self.weights, self.heights)
        out = replace(out, vectors=vectors)
        self.contacts, self.sigma = out.contacts[0], float(out.sigma[0])
        err, flag, _ = m.confidence(out)
        self.error_m = float(err[0])
        self.unreliable = bool(flag[0]) if flag is not None else False
        rot, raw_root = self.integrator.step(out.vectors[0])
        sk = m.skeleton_
        # the feet only (a tenth of a whole-body fk's cost for one frame)
        feet = joint_positions(rot, raw_root, sk.offsets, sk.parents, self.feet)
        root = self.pinner.step(raw_root, feet - raw_root, self.contacts)
        feet = feet - raw_root + root  # the lock's feet too (checked in __init__)
        c = self.contacts
        targets = self.lock.targets(feet, c[:2], c[2:])
        turns = self.lock.turn
        if not self.lock.moved(feet, targets, turns).any():  # no leg to bend
            return rot, root
        return self.lock.bend(rot[None], root[None], targets[None], turns=turns[None])[0], root
