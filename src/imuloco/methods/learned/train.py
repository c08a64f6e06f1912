"""Training data and the training loop of the ``learned`` method.

Augmentation (what real use brings that the benchmark's one noise draw per clip does not):
every clip is simulated again ``draws`` times, each time with its own seed, a random speed
change (the motion time-resampled by a factor in ``1 +- speed`` before simulating), the noise
preset's levels scaled by a log-uniform factor up to ``noise_scale`` (white noise, biases,
timestamp jitter, misalignment, placement offset), other body proportions (the sensor simulated
on a body :func:`proportioned` by up to ``proportions``; the targets stay on the training
skeleton), every other draw left/right mirrored (:func:`imuloco.core.mirror.mirror`), so
that a model learns both legs' gaits from one sensor, a fraction ``reverse`` of the draws
played backwards in time (:func:`reversed_motion`), a fraction ``strap`` worn on a random
soft-tissue strap (:mod:`imuloco.sensors.strap`) and every sensor turned about its
medio-lateral axis by up to ``incline`` degrees (:func:`inclined`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch
from tqdm.auto import tqdm

from imuloco.core.mirror import mirror, mirror_frames
from imuloco.core.motion import Motion
from imuloco.core.recording import Recording
from imuloco.methods import pose
from imuloco.methods.learned.model import Reconstructor, TorchFK, rotation_from_6d
from imuloco.methods.training import Example, clip_seed, to_frames
from imuloco.ops.filters import resample_linear
from imuloco.ops.kinematics import fk
from imuloco.ops.rotations import from_6d, qinv, qmul, qrot, slerp
from imuloco.phases.contacts import foot_contacts
from imuloco.sensors.noise import NoiseModel, get_noise
from imuloco.sensors.simulate import simulate
from imuloco.sensors.strap import random_strap

DRAW_SEED_STRIDE = 7919  # seeds of augmented draws: seed + stride * draw


def speed_change(motion: Motion, factor: float) -> Motion:
    """The motion played ``factor`` times faster (fewer frames at the same fps), rotations
    slerped and the root interpolated linearly."""
    n = max(round((motion.num_frames - 1) / factor) + 1, 2)
    src = motion.times
    new = np.minimum(np.arange(n) * factor / motion.fps, src[-1])
    rot = slerp(motion.rotations, src, new)
    root = resample_linear(src, motion.root, new)
    return Motion(motion.skeleton, rot, root, motion.fps, motion.name)


def scaled_noise(model: NoiseModel, scale: float, misplace: float) -> NoiseModel:
    """A noise model with white noise, biases and jitter times ``scale`` and misalignment and
    offset times ``misplace``."""
    return replace(model, name=f"{model.name}*{scale:.2f}", acc_noise=model.acc_noise * scale,
                   gyro_noise=model.gyro_noise * scale, acc_bias=model.acc_bias * scale,
                   gyro_bias=model.gyro_bias * scale, jitter_s=model.jitter_s * scale,
                   misalignment_deg=model.misalignment_deg * misplace,
                   offset_m=model.offset_m * misplace)


def reversed_motion(motion: Motion) -> Motion:
    """``motion`` played backwards in time. Walking backwards is close to forward walking
    reversed in time (Winter, Pluck and Yang 1989: the joint angle patterns of the two nearly
    mirror each other in time), so reversed forward walks stand in for backward walking."""
    return Motion(motion.skeleton, motion.rotations[::-1].copy(), motion.root[::-1].copy(),
                  motion.fps, motion.name)


def proportioned(motion: Motion, rng: np.random.Generator, spread: float) -> Motion:
    """``motion`` played by a body of other proportions: the whole body scaled by a factor in
    ``1 +- spread`` (height), then the legs, the arms and the trunk (with head and pelvis
    width) each by a further factor in ``1 +- spread / 2``; rotations unchanged, the root path
    scaled with the legs (so that the feet keep their ground contacts). What a sensor on a
    taller, shorter or longer-legged wearer reads; ``spread`` 0 returns ``motion``."""
    if spread <= 0:
        return motion
    sk = motion.skeleton
    height = rng.uniform(1 - spread, 1 + spread)
    legs, arms, trunk = rng.uniform(1 - spread / 2, 1 + spread / 2, 3)
    factor = np.full(sk.num_joints, trunk)
    tops = {f"{s}_{p}": f for s in ("left", "right") for p, f in (("hip", legs),
                                                                  ("shoulder", arms))}
    if not set(tops) <= set(sk.body_map or {}):  # limbs unknown: one factor for all
        tops, legs = {}, trunk
    limbs = [(sk.part(p), f) for p, f in tops.items()]
    for top, f in limbs:  # every joint below a hip or shoulder: that limb's segments
        below = np.zeros(sk.num_joints, bool)
        for j in range(sk.num_joints):
            below[j] = sk.parents[j] == top or (sk.parents[j] >= 0 and below[sk.parents[j]])
        factor[below] = f
    k = height * factor
    skel = type(sk)(list(sk.names), sk.parents.copy(), sk.offsets * k[:, None],
                    {j: v * k[j] for j, v in sk.end_sites.items()},
                    dict(sk.body_map or {}))
    return Motion(skel, motion.rotations, motion.root * (height * legs), motion.fps, motion.name)


def inclined(rec: Recording, degrees: np.ndarray) -> Recording:
    """``rec`` read by sensors turned about their own x (medio-lateral) axis by ``degrees``
    (S,), one angle a sensor: a constant rotation of a sensor on its segment only rotates its
    signals. Stands for the uncertainty of the calibration's up axis, which is gravity at rest
    or the walk's mean force turned by a prior (:mod:`imuloco.sensors.calibration`)."""
    a = np.deg2rad(np.asarray(degrees, float))
    q = np.zeros((len(a), 4))
    q[:, 0], q[:, 3] = np.sin(a / 2), np.cos(a / 2)
    # readings in the turned frame: the inverse rotation applied to the old frame's vectors
    qi = qinv(q)[None]
    return replace(rec, acc=qrot(qi, rec.acc), gyro=qrot(qi, rec.gyro), orientation=None
                   if rec.orientation is None else qmul(rec.orientation, q[None]))


def contact_targets(motion: Motion) -> np.ndarray:
    """Heel and toe contacts (T, 4) in :data:`CONTACT_PARTS` order, from
    :func:`imuloco.phases.contacts.foot_contacts`."""
    c = foot_contacts(motion)
    return np.stack([c["left_heel"], c["right_heel"], c["left_toe"], c["right_toe"]],
                    axis=1).astype(np.float32)


def augment(examples: list[Example], placements: list[str], noise: str, seed: int,
            draws: int, speed: float, noise_scale: float, mirrored: bool,
            progress: bool = False, proportions: float = 0.0,
            reverse: float = 0.0, strap: float = 0.0, incline: float = 0.0
            ) -> list[Example]:
    """The benchmark's examples plus ``draws`` augmented simulations of every clip (see the
    module docstring). Draw ``d`` mirrors the motion when ``mirrored`` and ``d`` is odd; each
    augmented clip is reversed in time with probability ``reverse``, and its sensors sit on a
    random soft-tissue strap (:func:`imuloco.sensors.strap.random_strap`) with probability
    ``strap``, and its sensors are turned about their x axes by angles uniform in
    ``+-incline`` degrees (:func:`inclined`)."""
    out = list(examples)
    if draws <= 0:
        return out
    base = get_noise(noise)
    frames = mirror_frames([e.motion for e in examples]) if mirrored else None
    rng = np.random.default_rng(seed + 1)
    tilt_rng = np.random.default_rng([seed, 16])  # its own stream: other draws stay the same
    jobs = [(d, e) for d in range(1, draws + 1) for e in examples]
    for d, e in tqdm(jobs, desc="augmenting", disable=not progress, unit="clip"):
        motion = e.motion
        if mirrored and d % 2 == 1:
            motion = mirror(motion, frames)
        f = rng.uniform(1 - speed, 1 + speed) if speed > 0 else 1.0
        if abs(f - 1) > 1e-3:
            motion = speed_change(motion, f)
        s = math.exp(rng.uniform(-1, 1) * math.log(noise_scale)) if noise_scale > 1 else 1.0
        model = scaled_noise(base, s, rng.uniform(0.5, 1.5))
        if reverse > 0 and rng.uniform() < reverse:
            motion = reversed_motion(motion)
        body = proportioned(motion, rng, proportions)
        worn = random_strap(rng) if strap > 0 and rng.uniform() < strap else None
        rec = simulate(body, placements, 100.0, model,
                       clip_seed(e.labels["name"], seed + DRAW_SEED_STRIDE * d), worn)
        if incline > 0:
            rec = inclined(rec, tilt_rng.uniform(-incline, incline, len(placements)))
        out.append(Example(motion, to_frames(rec, motion), dict(e.labels, draw=str(d))))
    return out


@dataclass
class Arrays:
    """Training arrays of one set of clips, concatenated, with clip bounds."""

    x: np.ndarray        # (N, C) standardized signals
    y: np.ndarray        # (N, D) standardized pose vectors
    contacts: np.ndarray  # (N, 4)
    positions: np.ndarray  # (N, J, 3) joint positions, root at the origin, heading frame
    starts: np.ndarray   # (K,) first row of each clip
    lengths: np.ndarray  # (K,)


def stack(examples: list[Example]) -> tuple[np.ndarray, ...]:
    """Raw signals (N, C), pose vectors (N, D), contacts (N, 4), joint positions (N, J, 3)
    (root at the origin, in the heading frame) and clip lengths (K,)."""
    xs, ys, cs, ps = [], [], [], []
    for e in examples:
        sk = e.motion.skeleton
        y = pose.encode(e.motion)
        rot = from_6d(y[:, : 6 * sk.num_joints].reshape(len(y), -1, 6))
        ps.append(fk(rot, np.zeros(3), sk.offsets, sk.parents)[1].astype(np.float32))
        xs.append(np.nan_to_num(e.signals).astype(np.float32))
        ys.append(y.astype(np.float32))
        cs.append(contact_targets(e.motion))
    lengths = np.array([len(x) for x in xs])
    return (np.concatenate(xs), np.concatenate(ys), np.concatenate(cs), np.concatenate(ps),
            lengths)


def windows(lengths: np.ndarray, starts: np.ndarray, size: int, rng: np.random.Generator
            ) -> list[tuple[int, int]]:
    """Non-overlapping windows (start row, length) covering every clip from a random offset."""
    out = []
    for s, n in zip(starts, lengths):
        off = int(rng.integers(0, size)) if n > size else 0
        first = off - size if off > 0 else 0
        for a in range(first, n, size):
            lo = max(a, 0)
            hi = min(a + size, n)
            if hi - lo >= 8:
                out.append((int(s + lo), hi - lo))
    return out


@dataclass
class LossWeights:
    """Weights of the loss terms (see :func:`losses`)."""

    position: float = 10.0
    smooth: float = 30.0
    accel: float = 150.0
    contact: float = 0.5
    confidence: float = 0.1


def losses(net: Reconstructor, fk: TorchFK, y_mean: torch.Tensor, y_std: torch.Tensor,
           x: torch.Tensor, y: torch.Tensor, c: torch.Tensor, pt: torch.Tensor,
           mask: torch.Tensor, w: LossWeights) -> dict[str, torch.Tensor]:
    """Loss terms of a batch (B, T, .), target positions ``pt`` (B, T, J, 3), ``mask``
    (B, T) marking real frames.

    - ``pose``: squared error of the standardized pose vector (rotations, height, velocity);
    - ``position``: mean joint position error (m) through FK, root at the origin;
    - ``smooth``: error of the frame-to-frame joint displacement (m), against jitter;
    - ``accel``: error of the second difference of joint positions (m), against jitter;
    - ``contact``: binary cross-entropy of heel and toe contacts;
    - ``nll``: Gaussian negative log-likelihood of the (detached) squared position error
      under the predicted log-variance.
    """
    pred, logit, logvar, _ = net(x)
    m = mask.unsqueeze(-1)
    count = mask.sum().clamp(min=1)
    out = {"pose": (((pred - y) ** 2) * m).sum() / (count * y.shape[-1])}
    j = fk.offsets.shape[0]
    rot_p = rotation_from_6d((pred * y_std + y_mean)[..., : 6 * j].reshape(*pred.shape[:2], j, 6))
    pp = fk(rot_p)
    err = (pp - pt).norm(dim=-1)                                # (B, T, J)
    out["position"] = (err.mean(-1) * mask).sum() / count
    dm = mask[:, 1:] * mask[:, :-1]
    derr = ((pp[:, 1:] - pp[:, :-1]) - (pt[:, 1:] - pt[:, :-1])).norm(dim=-1).mean(-1)
    out["smooth"] = (derr * dm).sum() / dm.sum().clamp(min=1)
    am = dm[:, 1:] * dm[:, :-1]
    acc_p = pp[:, 2:] - 2 * pp[:, 1:-1] + pp[:, :-2]
    acc_t = pt[:, 2:] - 2 * pt[:, 1:-1] + pt[:, :-2]
    aerr = (acc_p - acc_t).norm(dim=-1).mean(-1)
    out["accel"] = (aerr * am).sum() / am.sum().clamp(min=1)
    bce = torch.nn.functional.binary_cross_entropy_with_logits(logit, c, reduction="none")
    out["contact"] = (bce * m).sum() / (count * c.shape[-1])
    e2 = (err.detach() ** 2).mean(-1)
    s = logvar.squeeze(-1)
    out["nll"] = ((0.5 * (torch.exp(-s) * e2 + s)) * mask).sum() / count
    out["total"] = (out["pose"] + w.position * out["position"] + w.smooth * out["smooth"]
                    + w.accel * out["accel"]
                    + w.contact * out["contact"] + w.confidence * out["nll"])
    return out


def batches(arrays: Arrays, wins: list[tuple[int, int]], size: int, batch: int,
            rng: np.random.Generator, shuffle: bool = True):
    """Padded batches (x, y, contacts, mask) of windows."""
    order = rng.permutation(len(wins)) if shuffle else np.arange(len(wins))
    for b in range(0, len(order), batch):
        sel = [wins[i] for i in order[b:b + batch]]
        t = max(n for _, n in sel)
        x = np.zeros((len(sel), t, arrays.x.shape[1]), np.float32)
        y = np.zeros((len(sel), t, arrays.y.shape[1]), np.float32)
        c = np.zeros((len(sel), t, arrays.contacts.shape[1]), np.float32)
        p = np.zeros((len(sel), t) + arrays.positions.shape[1:], np.float32)
        mask = np.zeros((len(sel), t), np.float32)
        for i, (s, n) in enumerate(sel):
            x[i, :n], y[i, :n] = arrays.x[s:s + n], arrays.y[s:s + n]
            c[i, :n], mask[i, :n] = arrays.contacts[s:s + n], 1.0
            p[i, :n] = arrays.positions[s:s + n]
            if n < t:  # padding repeats the last target so that differences stay finite
                y[i, n:], p[i, n:] = y[i, n - 1], p[i, n - 1]
        yield (torch.from_numpy(x), torch.from_numpy(y), torch.from_numpy(c),
               torch.from_numpy(p), torch.from_numpy(mask))


def train(net: Reconstructor, fk: TorchFK, train_set: Arrays, val_set: Arrays | None,
          y_mean: np.ndarray, y_std: np.ndarray, epochs: int, batch: int, window: int,
          lr: float, weights: LossWeights, seed: int, progress: bool = False,
          weight_decay: float = 1e-4) -> list[dict]:
    """Adam with a one-cycle learning-rate schedule; returns one dict of mean losses per epoch
    (training terms, and the validation position error in metres when ``val_set`` is given)."""
    rng = np.random.default_rng(seed)
    torch.manual_seed(seed)
    ym = torch.as_tensor(y_mean, dtype=torch.float32)
    ys = torch.as_tensor(y_std, dtype=torch.float32)
    steps = epochs * math.ceil(len(windows(train_set.lengths, train_set.starts, window, rng))
                               / batch)
    opt = torch.optim.AdamW(net.parameters(), lr=lr, weight_decay=weight_decay)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=lr, total_steps=max(steps, 1),
                                                pct_start=0.15)
    history: list[dict] = []
    t0 = time.perf_counter()
    done = 0
    for epoch in range(epochs):
        net.train()
        wins = windows(train_set.lengths, train_set.starts, window, rng)
        sums: dict[str, float] = {}
        nb = 0
        bar = tqdm(list(batches(train_set, wins, window, batch, rng)), disable=not progress,
                   desc=f"epoch {epoch + 1}/{epochs}", unit="batch", leave=False)
        for x, y, c, p, mask in bar:
            terms = losses(net, fk, ym, ys, x, y, c, p, mask, weights)
            opt.zero_grad()
            terms["total"].backward()
            torch.nn.utils.clip_grad_norm_(net.parameters(), 1.0)
            opt.step()
            if done < steps:
                sched.step()
                done += 1
            for k, v in terms.items():
                sums[k] = sums.get(k, 0.0) + v.item()
            nb += 1
        rec = {k: v / max(nb, 1) for k, v in sums.items()}
        rec["epoch"] = epoch + 1
        rec["seconds"] = time.perf_counter() - t0
        if val_set is not None and len(val_set.lengths):
            rec["val_position"] = evaluate(net, fk, val_set, ym, ys, weights)
        history.append(rec)
        if progress:
            tqdm.write(" ".join(f"{k}={v:.4g}" for k, v in rec.items()))
    return history


@torch.no_grad()
def evaluate(net: Reconstructor, fk: TorchFK, arrays: Arrays, ym: torch.Tensor,
             ys: torch.Tensor, weights: LossWeights) -> float:
    """Mean joint position error (m, root-relative) over whole clips run from a zero state."""
    net.eval()
    total, count = 0.0, 0
    wins = [(int(s), int(n)) for s, n in zip(arrays.starts, arrays.lengths)]
    for x, y, c, p, mask in batches(arrays, wins, 0, 16, np.random.default_rng(0),
                                    shuffle=False):
        terms = losses(net, fk, ym, ys, x, y, c, p, mask, weights)
        n = float(mask.sum())
        total += float(terms["position"]) * n
        count += int(n)
    return total / max(count, 1)


def plot_history(history: list[dict], path: str | Path) -> Path | None:
    """Training curves (loss terms and validation position error per epoch) as a PNG; None
    when matplotlib is not installed."""
    try:  # the [viz] extra's
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    members = sorted({h.get("member", 0) for h in history})  # an ensemble's, one by one
    for m in members:
        rows = [h for h in history if h.get("member", 0) == m]
        epochs = [h["epoch"] for h in rows]
        tag = f" ({m})" if len(members) > 1 else ""
        for key in ("total", "pose", "contact"):
            axes[0].plot(epochs, [h[key] for h in rows], label=key + tag)
        axes[1].plot(epochs, [100 * h["position"] for h in rows], label="training" + tag)
        if "val_position" in rows[0]:
            axes[1].plot(epochs, [100 * h["val_position"] for h in rows],
                         label="validation" + tag)
    axes[0].set_xlabel("epoch")
    axes[0].set_title("training losses")
    axes[0].legend(fontsize="small")
    axes[1].set_xlabel("epoch")
    axes[1].set_ylabel("cm")
    axes[1].set_title("mean joint position error (root-relative, heading frame)")
    axes[1].legend(fontsize="small")
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
