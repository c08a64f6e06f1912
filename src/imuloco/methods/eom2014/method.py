"""Eom, Choi, Noh 2014: GPLVM + velocity GP, HMM phase segmentation, per-phase MLP.

Pipeline (paper section in brackets):

1. Signals are smoothed by a 1-D Gaussian per dimension [4.1] (``sigma`` frames; the paper
   gives no width).
2. Training clips are cut into the paper's coarse phases by foot contact [5.4, Fig. 4] with
   :func:`imuloco.phases.gait_phases` (``eom2014`` labels: start, first_step, right_step,
   left_step, stop) instead of by hand.
3. One GPLVM with a velocity GP [5.1-5.3] per motion type (``per_type=True``, the paper's
   "a GPLVM model for each motion type", sec. 7) or one over all types. Pose vectors y are the
   6-D local joint rotations (the root's relative to the heading) and the root height from
   :mod:`imuloco.methods.pose`; the velocity vectors are ``y_i - y_{i-1}`` (per second) plus the
   root's horizontal velocity in the heading frame and the yaw rate ("horizontal world
   translation", sec. 5.2).
4. GP cost is cubic in frames: each model learns on an *active set* of at most ``n_active``
   frames (the paper: 65-136 frames of one clip). The set is made of whole phase segments
   (at most ``max_segment`` frames each, so velocities stay defined inside them) picked by
   farthest-point sampling on the segments' poses at four instants, so every kind of step in
   the training data is represented. The other training frames (an even subsample of at most
   :data:`MAX_REGRESSION_FRAMES` per model) get latent points by back-projection
   (:meth:`GPLVM.project`), so that the MLPs learn from many frames; the paper trained GPLVM and
   MLP on the same single clip and needed none.
5. Per phase, discrete HMMs on 3-level slope codes [5.4], and an MLP from the smoothed sensor
   frame to its latent point [5.5]. The paper's MLP input is the (smoothed) sensor frame of the
   phase's block; ``context`` > 0 adds neighbouring frames (not in the paper; 0 by default).
6. Reconstruction [6]: phases by majority vote of moving windows [6.1], latent points from
   the phase's MLP, poses from the GP mean (eq. 7), root velocity from the velocity GP's mean at
   ``[x_t, x_t - x_{t-1}]``, Laplacian smoothing of the joint rotations with SLERP (and, not
   in the paper, the same smoothing of the root height, velocity and yaw rate: unsmoothed they
   made the world positions several times jerkier than the ground truth), and foot skate
   clean-up with contacts detected on the result [6.2]
   (:func:`imuloco.phases.foot_contacts`, :func:`imuloco.methods.postprocess.pin_feet`). The
   paper's inverse kinematics step is not reproduced.

Choosing the type at test time (``per_type=True``): the paper knows each test clip's type. Here
every type's phase HMMs score the clip (mean over windows of the phase-marginal window
likelihood, :func:`~imuloco.methods.eom2014.hmm.sequence_score`) and the best type's model
reconstructs it; the ablation variants choose the type the same way.

Ablation (Fig. 8 and 9), ``variant``:

- ``"full"``: everything above.
- ``"mlp-no-hmm"``: one MLP over all phases, no phase segmentation (third row of Fig. 8).
- ``"linear-latent"``: linear least squares from the sensor frame to the latent point (second
  row). The first row, linear regression straight to poses, is the ``ridge`` baseline.

Online (:meth:`Eom2014.stream`, not in the paper, which needs the whole sequence): the Gaussian
filter uses only past samples (half kernel, so it lags), the phase of frame t is that of the
window ending at t (no vote), the type is the best summed window score so far, the Laplacian
smoothing becomes exponential smoothing of the output, ``q_t <- slerp(q_t, q_{t-1}, a)`` (root
height, velocity and yaw rate alike) with ``a = s / (1 + s)``, ``s = sqrt(smooth_iterations *
smooth_lambda)`` (about the offline smoothing's width), and no foot clean-up is done.
"""

from __future__ import annotations

import itertools
import time
from typing import Any, ClassVar

import numpy as np

from imuloco.core.motion import Motion
from imuloco.methods import pose
from imuloco.methods.base import Method, Stream
from imuloco.methods.eom2014 import hmm as hmm_mod
from imuloco.methods.eom2014 import mlp as mlp_mod
from imuloco.methods.eom2014.gplvm import GPLVM, fit_gplvm
from imuloco.methods.params import Constraint, Options
from imuloco.methods.postprocess import (
    laplacian_smooth,
    laplacian_smooth_quaternions,
    pin_detected_contacts,
)
from imuloco.methods.training import TrainingSet
from imuloco.ops.filters import gaussian_smooth
from imuloco.ops.rotations import (
    about_y,
    from_6d,
    qmul,
    qrot,
    slerp_toward,
)
from imuloco.phases import gait_phases

VARIANTS = ("full", "mlp-no-hmm", "linear-latent")
MAX_REGRESSION_FRAMES = 12000  # training frames per model given latent points for the MLPs
_GP_FIELDS = ("x", "y_mean", "y_alpha", "alpha", "w", "cur", "prev", "v_mean", "v_alpha",
              "beta", "wv")


def farthest_point_order(points: np.ndarray, first: int) -> np.ndarray:
    """Indices of points (n, f) in farthest-point order from ``first`` (greedy k-center)."""
    n = len(points)
    order = np.empty(n, dtype=np.int64)
    order[0] = first
    dist = ((points - points[first]) ** 2).sum(1)
    for i in range(1, n):  # sequential by nature: each pick depends on all previous picks
        order[i] = int(np.argmax(dist))
        dist = np.minimum(dist, ((points - points[order[i]]) ** 2).sum(1))
    return order


def _runs(labels: np.ndarray, max_len: int) -> list[tuple[int, int, int]]:
    """Runs of equal labels (T,) as (label, start, stop), cut into pieces of <= max_len."""
    edges = np.flatnonzero(labels[1:] != labels[:-1]) + 1
    starts, stops = np.r_[0, edges], np.r_[edges, len(labels)]
    out = []
    for a, b in zip(starts, stops):
        n = int(np.ceil((b - a) / max_len))
        cuts = np.linspace(a, b, n + 1).round().astype(int)
        out += [(int(labels[a]), int(c0), int(c1)) for c0, c1 in itertools.pairwise(cuts)]
    return out


class _Model:
    """One motion type's learned parts: GPLVM, phase HMMs, regressors."""

    def __init__(self, gp: GPLVM, phases: list[int], hmms: hmm_mod.PhaseHMMs | None,
                 regs: list[list[np.ndarray]]) -> None:
        self.gp, self.phases, self.hmms, self.regs = gp, phases, hmms, regs


class Eom2014(Method):
    """Eom, Choi, Noh 2014 (see the module docstring for the pipeline and every choice)."""

    summary = "GPLVM + velocity GP, HMM phases, per-phase MLP (Eom et al. 2014)"
    # upper bounds far beyond any useful value, where a larger one only exhausted memory or
    # time: latent_dim 100 (the paper's is 5; a latent space as wide as the pose vectors, 6 J +
    # 4, reduces nothing), levels and n_states 100 (3 and 4 by default), sigma 1000 frames (the
    # filter then flattens any clip: 33 s at 30 fps; 1e300 overflowed scipy's kernel), maxiter
    # 10^4 (L-BFGS stops long before), MLP widths 4096 (32), context 300 frames each side
    # (10 s at 30 fps; the inputs grow 12 S per frame of it), smooth_iterations 10^4 (a
    # Laplacian of width sqrt(10^4 lambda), 70 frames at the default lambda)
    param_constraints: ClassVar[dict[str, Constraint]] = {
        "latent_dim": "[1, 100]", "window": "[1, inf)", "levels": "[1, 100]",
        "n_states": "[1, 100]", "sigma": "[0, 1000]", "n_active": "[1, inf)",
        "max_segment": "[2, inf)", "maxiter": "[0, 10000]", "x_prior": "[0, inf)",
        "hidden": "[1, 4096]", "context": "[0, 300]", "smooth_lambda": "[0, 1]",
        "smooth_iterations": "[0, 10000]", "min_phase_frames": "[0, inf)", "seed": "[0, inf)",
        "variant": Options(*VARIANTS)}
    supports_online = True

    def __init__(
        self,
        variant: str = "full",        # Fig. 8/9 ablation: full | mlp-no-hmm | linear-latent
        per_type: bool = True,        # one model per motion type, sec. 7
        latent_dim: int = 5,          # latent dimension, sec. 7
        window: int = 15,             # majority-vote window v, sec. 6.1 / 7 (10-20)
        levels: int = 3,              # slope discretization levels, sec. 5.4 / 7
        n_states: int = 4,            # hidden states per HMM (not given)
        sigma: float = 2.0,           # Gaussian filter of the signals, frames, sec. 4.1
        n_active: int = 300,          # GP training frames per model (paper: 65-136)
        max_segment: int = 30,        # longest contiguous piece of the active set, frames
        maxiter: int = 300,           # L-BFGS iterations for eq. 6, sec. 5.3
        x_prior: float = 1.0,         # unit Gaussian prior on X (Lawrence 2005), 0 = eq. 6
        hidden: tuple[int, ...] = (32,),  # MLP hidden layers, sec. 5.5 (size not given)
        context: int = 0,             # sensor frames on each side fed to the MLP (paper: 0)
        smooth_lambda: float = 0.5,   # Laplacian smoothing step, sec. 6.2
        smooth_iterations: int = 10,  # Laplacian smoothing passes, sec. 6.2 (not given)
        foot_cleanup: bool = True,    # foot-skate clean-up on detected contacts, sec. 6.2
        min_phase_frames: int = 60,   # phases with fewer training frames are dropped
        seed: int = 0,
    ) -> None:
        self.variant = variant
        self.per_type = per_type
        self.latent_dim = latent_dim
        self.window = window
        self.levels = levels
        self.n_states = n_states
        self.sigma = sigma
        self.n_active = n_active
        self.max_segment = max_segment
        self.maxiter = maxiter
        self.x_prior = x_prior
        self.hidden = tuple(hidden)
        self.context = context
        self.smooth_lambda = smooth_lambda
        self.smooth_iterations = smooth_iterations
        self.foot_cleanup = foot_cleanup
        self.min_phase_frames = min_phase_frames
        self.seed = seed

    # ---- features ------------------------------------------------------------------------
    def _smooth(self, signals: np.ndarray) -> np.ndarray:
        return gaussian_smooth(np.asarray(signals, dtype=np.float64), self.sigma)

    def _features(self, smooth: np.ndarray) -> np.ndarray:
        """MLP input per frame: the smoothed sensor frame, with ``context`` frames each side."""
        if self.context == 0:
            return smooth
        t = len(smooth)
        idx = np.clip(np.arange(t)[:, None] + np.arange(-self.context, self.context + 1),
                      0, t - 1)
        return smooth[idx].reshape(t, -1)

    # ---- learning ------------------------------------------------------------------------
    def learn(self, data: TrainingSet, progress: bool = False) -> None:
        t0 = time.perf_counter()
        j = data.skeleton.num_joints
        clips = []
        for e in data.examples:
            enc = pose.encode(e.motion)
            clips.append({
                "y": enc[:, :6 * j + 1], "root": enc[:, 6 * j + 1:],
                "s": self._smooth(e.signals), "phase": gait_phases(e.motion).eom2014,
                "type": e.labels.get("content", "all") if self.per_type else "all",
            })
        self.edges_ = hmm_mod.fit_levels([c["s"] for c in clips], self.levels)
        for c in clips:
            c["codes"] = hmm_mod.discretize(c["s"], self.edges_)
        self.types_ = sorted({c["type"] for c in clips})
        self.models_, self.fit_seconds_ = [], []
        for k, typ in enumerate(self.types_):
            t1 = time.perf_counter()
            self.models_.append(self._fit_model([c for c in clips if c["type"] == typ],
                                                data.fps, self.seed + k))
            self.fit_seconds_.append(time.perf_counter() - t1)
            if progress:
                print(f"eom2014: model {typ!r} in {self.fit_seconds_[-1]:.1f} s")
        self.fit_total_seconds_ = time.perf_counter() - t0

    def _fit_model(self, clips: list[dict[str, Any]], fps: float, seed: int) -> _Model:
        # active set: whole phase segments in farthest-point order of their poses
        y_all = np.concatenate([c["y"] for c in clips])
        scale = 1.0 / np.maximum(y_all.std(0), 1e-6)
        segs, desc = [], []
        for ci, c in enumerate(clips):
            for _, a, b in _runs(c["phase"], self.max_segment):
                if b - a >= 2:
                    at = np.linspace(a, b - 1, 4).round().astype(int)
                    segs.append((ci, a, b))
                    desc.append((c["y"][at] * scale).ravel())
        desc = np.asarray(desc)
        first = int(np.argmin(((desc - desc.mean(0)) ** 2).sum(1)))
        chosen, total = [], 0
        for i in farthest_point_order(desc, first):
            if total >= self.n_active:
                break
            chosen.append(segs[i])
            total += segs[i][2] - segs[i][1]
        ys, vs, cur, prev, n = [], [], [], [], 0
        for ci, a, b in chosen:
            c = clips[ci]
            y = c["y"][a:b]
            ys.append(y)
            vs.append(np.concatenate([np.diff(y, axis=0) * fps, c["root"][a + 1:b]], axis=1))
            cur.append(np.arange(n + 1, n + b - a))
            prev.append(np.arange(n, n + b - a - 1))
            n += b - a
        gp = fit_gplvm(np.concatenate(ys), np.concatenate(vs), np.concatenate(cur),
                       np.concatenate(prev), self.latent_dim, self.maxiter, self.x_prior)

        # latent points of all training frames (back-projection), features, phases
        # (an even subsample of at most MAX_REGRESSION_FRAMES bounds the cost)
        feats = np.concatenate([self._features(c["s"]) for c in clips])
        phase = np.concatenate([c["phase"] for c in clips])
        if len(y_all) > MAX_REGRESSION_FRAMES:
            sub = np.linspace(0, len(y_all) - 1, MAX_REGRESSION_FRAMES).round().astype(int)
            y_all, feats, phase = y_all[sub], feats[sub], phase[sub]
        x_all = gp.project(y_all)
        kept = [p for p in np.unique(phase) if (phase == p).sum() >= self.min_phase_frames]
        if not kept:
            kept = [int(np.bincount(phase).argmax())]
        hmms = None
        if self.variant == "full" or self.per_type:
            blocks: list[list[np.ndarray]] = [[] for _ in kept]
            for c in clips:
                for p, a, b in _runs(c["phase"], len(c["phase"])):
                    if p in kept:
                        blocks[kept.index(p)].append(c["codes"][a:b])
            hmms = hmm_mod.fit_phase_hmms(blocks, self.levels, self.n_states, seed=seed)
        if self.variant == "full":
            regs = [mlp_mod.fit_mlp(feats[phase == p], x_all[phase == p], self.hidden,
                                    seed=seed) for p in kept]
        elif self.variant == "mlp-no-hmm":
            regs = [mlp_mod.fit_mlp(feats, x_all, self.hidden, seed=seed)]
        else:
            regs = [mlp_mod.fit_linear(feats, x_all)]
        return _Model(gp, [int(p) for p in kept], hmms, regs)

    @property
    def pins_feet(self) -> bool:
        return self.foot_cleanup

    # ---- reconstruction ------------------------------------------------------------------
    def _choose(self, codes: np.ndarray) -> _Model:
        if len(self.models_) == 1:
            return self.models_[0]
        scores = [hmm_mod.sequence_score(codes, m.hmms, self.window) for m in self.models_]
        return self.models_[int(np.argmax(scores))]

    def latent(self, signals: np.ndarray) -> tuple[np.ndarray, np.ndarray, _Model]:
        """Latent points (T, q), phase per frame (T,) (index into the model's phases; zeros
        without HMM) and the model chosen for signals (T, 6 S) at the model rate."""
        s = self._smooth(signals)
        codes = hmm_mod.discretize(s, self.edges_)
        model = self._choose(codes)
        feats = self._features(s)
        if self.variant == "full" and len(model.regs) > 1:
            phase = hmm_mod.segment_phases(codes, model.hmms, self.window)
        else:
            phase = np.zeros(len(s), dtype=np.int64)
        x = np.empty((len(s), self.latent_dim))
        for p in np.unique(phase):
            x[phase == p] = mlp_mod.predict(model.regs[p], feats[phase == p])
        return x, phase, model

    def reconstruct_signals(self, signals: np.ndarray) -> Motion:
        signals = np.asarray(signals, dtype=np.float64)
        if signals.ndim != 2 or signals.shape[1] != self.edges_.shape[1]:
            raise ValueError(f"eom2014: expected signals (T, {self.edges_.shape[1]}), got "
                             f"{signals.shape}")
        x, _, model = self.latent(signals)
        y = model.gp.pose(x)
        v = model.gp.velocity(x, np.concatenate([x[:1], x[:-1]]))
        # root height, horizontal velocity and yaw rate: the same Laplacian smoothing as the
        # angles (the paper smooths "each angle value"; its root came out of the velocity GP
        # unsmoothed, which leaves the world positions jerky)
        root = laplacian_smooth(np.concatenate([y[:, -1:], v[:, -3:]], axis=1),
                                self.smooth_lambda, self.smooth_iterations)
        y[:, -1] = root[:, 0]
        motion = pose.decode(np.concatenate([y, root[:, 1:]], axis=1), self.skeleton_,
                             self.fps_)
        rot = laplacian_smooth_quaternions(motion.rotations, self.smooth_lambda,
                                           self.smooth_iterations)
        motion = Motion(motion.skeleton, rot, motion.root, motion.fps, motion.name)
        return pin_detected_contacts(motion) if self.foot_cleanup else motion

    def stream(self) -> Stream:
        return _Eom2014Stream(self)

    # ---- persistence ---------------------------------------------------------------------
    def get_state(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        arrays = {"edges": self.edges_}
        for i, m in enumerate(self.models_):
            for f in _GP_FIELDS:
                arrays[f"m{i}.gp.{f}"] = getattr(m.gp, f)
            if m.hmms is not None:
                arrays[f"m{i}.hmm.startprob"] = m.hmms.startprob
                arrays[f"m{i}.hmm.transmat"] = m.hmms.transmat
                arrays[f"m{i}.hmm.emission"] = m.hmms.emission
            for r, reg in enumerate(m.regs):
                for k, a in enumerate(reg):
                    arrays[f"m{i}.reg{r}.{k}"] = a
        values = {"types": self.types_, "phases": [m.phases for m in self.models_],
                  "reg_sizes": [[len(r) for r in m.regs] for m in self.models_],
                  "has_hmm": [m.hmms is not None for m in self.models_],
                  "fit_seconds": self.fit_seconds_}
        return arrays, values

    def set_state(self, arrays: dict[str, np.ndarray], values: dict[str, Any]) -> None:
        self.edges_ = arrays["edges"]
        self.types_ = list(values["types"])
        self.fit_seconds_ = list(values.get("fit_seconds", []))
        self.models_ = []
        for i in range(len(self.types_)):
            gp = GPLVM(**{f: arrays[f"m{i}.gp.{f}"] for f in _GP_FIELDS})
            hmms = None
            if values["has_hmm"][i]:
                hmms = hmm_mod.PhaseHMMs(arrays[f"m{i}.hmm.startprob"],
                                         arrays[f"m{i}.hmm.transmat"],
                                         arrays[f"m{i}.hmm.emission"])
            regs = [[arrays[f"m{i}.reg{r}.{k}"] for k in range(n)]
                    for r, n in enumerate(values["reg_sizes"][i])]
            self.models_.append(_Model(gp, list(values["phases"][i]), hmms, regs))


class _Eom2014Stream(Stream):
    """Causal variant (see the module docstring): bounded buffers of the last samples."""

    def __init__(self, method: Eom2014) -> None:
        self.m = method
        half = max(int(np.ceil(3 * method.sigma)), 0)
        w = np.exp(-0.5 * (np.arange(half, -1, -1) / max(method.sigma, 1e-9)) ** 2)
        self.kernel = w / w.sum()                   # oldest first, newest weight largest
        self.raw: list[np.ndarray] = []             # last len(kernel) raw samples
        self.smooth: list[np.ndarray] = []          # last window + context smoothed samples
        self.scores = np.zeros(len(method.models_))
        self.x_prev: np.ndarray | None = None
        self.model_index = -1
        self.rot_prev: np.ndarray | None = None
        self.theta = 0.0
        self.root = np.zeros(3)
        self.frames = 0
        width = np.sqrt(method.smooth_iterations * method.smooth_lambda)
        self.a = width / (1.0 + width)              # weight of the previous output
        self.track_prev = np.zeros(4)

    def step(self, sample: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        m = self.m
        sample = np.asarray(sample, dtype=np.float64)
        self.raw = (self.raw + [sample])[-len(self.kernel):]
        k = self.kernel[-len(self.raw):]
        s = (np.asarray(self.raw) * k[:, None]).sum(0) / k.sum()
        self.smooth = (self.smooth + [s])[-(max(m.window, 2 * m.context + 1) + 1):]
        hist = np.asarray(self.smooth)
        # codes of the last window: slope of the first frame of the buffer repeats the second
        codes = hmm_mod.discretize(hist, m.edges_)[-m.window:]
        if len(m.models_) > 1:
            self.scores += [hmm_mod.window_loglik(codes, mo.hmms, len(codes))[0].max()
                            for mo in m.models_]
        best = int(np.argmax(self.scores))
        if best != self.model_index:                # another latent space: no velocity yet
            self.x_prev, self.model_index = None, best
        model = m.models_[best]
        # MLP input: frames t - context .. t + context, the future ones replaced by frame t
        idx = np.clip(len(hist) - 1 + np.arange(-m.context, m.context + 1), 0, len(hist) - 1)
        feat = hist[idx].ravel()
        p = 0
        if m.variant == "full" and len(model.regs) > 1:
            p = int(np.argmax(hmm_mod.window_loglik(codes, model.hmms, len(codes))[0]))
        x = mlp_mod.predict(model.regs[p], feat[None])[0]
        x_prev = x if self.x_prev is None else self.x_prev
        self.x_prev = x
        y = model.gp.pose(x[None])[0]
        v = model.gp.velocity(x[None], x_prev[None])[0, -3:]
        j = m.skeleton_.num_joints
        rot = from_6d(y[:6 * j].reshape(j, 6))
        track = np.r_[y[6 * j], v]                  # root height, velocity (2), yaw rate
        if self.rot_prev is not None:               # causal exponential smoothing
            rot = slerp_toward(rot, self.rot_prev, self.a)
            track = (1 - self.a) * track + self.a * self.track_prev
            self.theta += track[3] / m.fps_
        self.track_prev = track
        self.rot_prev = rot
        yaw = about_y(np.array(self.theta))
        out = rot.copy()
        out[0] = qmul(yaw, rot[0])
        if self.frames > 0:
            step = qrot(yaw, np.array([track[1], 0.0, track[2]])) / m.fps_
            self.root = self.root + np.array([step[0], 0.0, step[2]])
        self.root[1] = track[0]
        self.frames += 1
        return out, self.root.copy()
