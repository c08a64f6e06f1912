"""Deep ensembles of ``learned`` models: several networks of one recipe trained from other
seeds read as one (:func:`ensemble`; the network is :class:`.model.Ensemble`), and how much
their members disagree on a frame (:func:`member_spread`), one more score for its predicted
error. The ensemble's members run in one pass over the signal (:meth:`.model.Ensemble.encode`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from imuloco.core.skeleton import Skeleton
from imuloco.errors import InputError
from imuloco.methods.base import Method
from imuloco.methods.learned.model import Ensemble
from imuloco.ops.kinematics import fk_matrices
from imuloco.ops.rotations import matrices_from_6d

if TYPE_CHECKING:
    from imuloco.methods.learned.method import Learned


# what members of one ensemble must share: they read the same signals and write the same poses
_SHARED = ("placements_", "noise_", "fps_", "channels_", "lag", "bidirectional", "hidden",
           "layers", "output_mirror_")


def ensemble(models: Sequence[Learned]) -> Learned:
    """One model that averages ``models`` (:class:`.model.Ensemble`): the same placements,
    noise, rate, skeleton, look-ahead, network shape and leg, trained from other seeds.

    The result keeps the first model's standardization and hyperparameters (``members`` set,
    ``seed`` the first's), each member's protocol and history, the members' mean novelty
    (:func:`_mean_novelty`) and no calibration (``imuloco calibrate``). Raises InputError
    naming the member and what differs.
    """
    models = list(models)
    if len(models) < 2:
        raise InputError(f"an ensemble needs at least 2 learned models, got {len(models)}")
    first = models[0]
    for i, m in enumerate(models):
        learned = isinstance(m, Method) and m.name == "learned"
        if not learned or isinstance(getattr(m, "net_", None), Ensemble):
            raise InputError(f"ensemble member {i}: expected a learned model of one network, "
                             f"got {type(m).__name__}" + (" (an ensemble)" if learned else ""))
        m.check_fitted()
        diff = [k for k in _SHARED if getattr(m, k) != getattr(first, k)]
        if m.skeleton_.names != first.skeleton_.names or not _same(m.skeleton_.offsets,
                                                                   first.skeleton_.offsets):
            diff.append("skeleton_")
        diff += [k for k in ("input_map_", "frames_")
                 if not _same(getattr(m, k), getattr(first, k))]
        if diff:
            raise InputError(f"ensemble member {i} differs from member 0 in "
                             + ", ".join(f"{k} ({getattr(m, k)!r} vs {getattr(first, k)!r})"
                                         if k not in ("skeleton_", "input_map_", "frames_")
                                         else k for k in diff))
    new = type(first)(**{**first.get_params(), "members": len(models)})
    new.set_setup(first.skeleton_, first.fps_, first.placements_, first.noise_)
    new.x_mean_, new.x_std_, new.y_mean_, new.y_std_ = (first.x_mean_, first.x_std_,
                                                        first.y_mean_, first.y_std_)
    new.input_map_, new.frames_ = first.input_map_, first.frames_
    new.output_mirror_ = first.output_mirror_
    # member k standardized its own augmented draws: maps to and from the first's folded in
    new.net_ = Ensemble([Ensemble.restandardized(
        m.net_, first.x_std_ / m.x_std_, (first.x_mean_ - m.x_mean_) / m.x_std_,
        m.y_std_ / first.y_std_, (m.y_mean_ - first.y_mean_) / first.y_std_) for m in models]
    ).eval()
    new.history_ = [{"member": k, **row} for k, m in enumerate(models) for row in m.history_]
    new.calibration_ = None
    new.flat_pitch_ = first.flat_pitch_  # the members learned from the same motions
    _mean_novelty(new, models)
    protocols = [{**getattr(m, "protocol_", {}), "model_seed": int(m.seed)} for m in models]
    new.protocol_ = {**protocols[0], "members": protocols,
                     "train_seconds": round(sum(p.get("train_seconds", 0.0)
                                                for p in protocols), 1)}
    return new


def member_spread(vectors: np.ndarray, skeleton: Skeleton) -> np.ndarray:
    """How much an ensemble's members disagree on a frame, metres: ``vectors`` (..., K, D)
    the members' pose vectors (K >= 2) -> (...) the rms over joints (but the root) of the
    standard deviation over the members (K - 1 in the denominator, so that any K estimates
    the same) of their root-relative joint positions in the heading frame (the forward
    kinematics of their local rotations). Where members trained from other seeds part ways,
    none of them knows the motion (Lakshminarayanan et al. 2017).

    Frame by frame alike, so a long recording's frames go :data:`SPREAD_FRAMES` at a time:
    the members' rotation matrices of one piece at once (K of a whole motion's: 0.5 GB at
    peak for a 640 s walk, 4 members, in one go)."""
    vectors = np.asarray(vectors)
    if vectors.ndim == 3 and len(vectors) > SPREAD_FRAMES:
        return np.concatenate([member_spread(vectors[i:i + SPREAD_FRAMES], skeleton)
                               for i in range(0, len(vectors), SPREAD_FRAMES)])
    j = skeleton.num_joints
    rot = matrices_from_6d(vectors[..., : 6 * j].reshape(*vectors.shape[:-1], j, 6))
    pos = fk_matrices(rot, np.zeros(rot.shape[:-3] + (3,)), skeleton.offsets,
                      skeleton.parents)[1][..., 1:, :]
    dev = np.square(pos - pos.mean(axis=-3, keepdims=True)).sum(axis=(-1, -3))
    return np.sqrt(dev.mean(axis=-1) / (vectors.shape[-2] - 1))


SPREAD_FRAMES = 2048  # frames a piece of :func:`member_spread`


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return np.shape(a) == np.shape(b) and bool(np.allclose(a, b))


def _mean_novelty(model: Learned, members: Sequence[Learned]) -> None:
    """An ensemble's novelty: its members' mean novelty, each against its own reference
    (fitted in training on its augmented draws), as one distance on the features side by side
    (the precision one (W, W) block per member); flagged above the members' mean threshold,
    which flags no more than each member's 1 % of held-out training frames on average. None
    when a member has no reference."""
    if any(m.novelty_mean_ is None for m in members):
        model.novelty_mean_ = None
        return
    model.novelty_mean_ = np.concatenate([m.novelty_mean_ for m in members])
    # Learned._novelty divides the distance by the feature count: K W here, W per member
    model.novelty_precision_ = np.stack([m.novelty_precision_ / m.novelty_scale_
                                         for m in members])
    model.novelty_scale_ = 1.0
    model.novelty_alpha_ = float(members[0].novelty_alpha_)
    model.novelty_threshold_ = float(np.mean([m.novelty_threshold_ for m in members]))
