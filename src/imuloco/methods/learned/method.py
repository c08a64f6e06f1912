"""``learned``: imuloco's own causal recurrent reconstructor (see :mod:`.model`).

Signals are standardized and fed to a GRU frame by frame; the root's predicted height is
averaged over a few frames either side (``height_smooth``), and the pose vectors are decoded
with :func:`imuloco.methods.pose.decode` (root path integrated from the predicted velocity and
yaw rate), then the feet predicted in contact are pinned (:func:`imuloco.methods.postprocess.
pin_feet`, heels at the ankle joints and toes at the toe joints: the root moves) and held
where they landed on the floor (:func:`imuloco.methods.postprocess.lock_feet`: the legs bend),
which removes foot skating.
:meth:`Learned.stream` does the same one frame at a time with the GRU's hidden state and gives
the offline result frame for frame.

A model for the other leg (:meth:`Learned.mirrored`) reuses the weights: the other leg's
signals are mapped onto this leg's sensor axes and the predicted pose is mirrored back.

Several models of one recipe trained from other seeds read as one (:func:`.ensemble.ensemble`,
or ``members`` > 1): their outputs are averaged (:class:`.model.Ensemble`), and how much they
disagree on a frame is one more score for its predicted error (``spread_m``,
:func:`.ensemble.member_spread`).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import torch

from imuloco.core.mirror import mirror_pairs
from imuloco.core.motion import Motion
from imuloco.errors import InputError
from imuloco.methods import pose
from imuloco.methods.base import Method, Reconstruction
from imuloco.methods.learned import train as tr
from imuloco.methods.learned.confidence import (  # noqa: F401  (their names here too)
    FLAG_QUANTILE,
    NOVELTY_TAU_S,
    SCORES,
    ConfidenceMixin,
    Prediction,
)
from imuloco.methods.learned.ensemble import ensemble, member_spread
from imuloco.methods.learned.mirroring import (  # noqa: F401
    CONTACT_SWAP,
    HEADING_REFLECTION,
    MirrorMixin,
)
from imuloco.methods.learned.model import Ensemble, Reconstructor, TorchFK
from imuloco.methods.learned.stream import (  # noqa: F401  (PIN_*: their names here too)
    PIN_PARTS,
    PIN_SMOOTHING,
    LearnedStream,
    lock,
    pin,
)
from imuloco.methods.params import Constraint
from imuloco.methods.postprocess import (
    gaussian_weights,
    window_average,
)
from imuloco.methods.training import VALIDATION_SHARE, Example, TrainingSet, held_out
from imuloco.phases.contacts import flat_foot_pitch


class Learned(ConfidenceMixin, MirrorMixin, Method):
    """A causal GRU from sensor channels to pose vectors, contacts and confidence.

    Parameters
    ----------
    hidden, layers : GRU width and depth.
    epochs, batch_size, window, lr : training schedule (windows of ``window`` frames, the
        one-cycle schedule's peak ``lr``). The network is under-trained rather than over-fitted
        at CPU budgets: on held-out styles (every third clip, docs/results/learned/
        experiments.md) MPJPE fell from 3.94 cm (128 wide, 10 epochs, batches of 32, lr 2e-3)
        to 3.71 with 20 epochs, 3.53 with batches of 16 and lr 4e-3, and 3.47 at width 192
        (the defaults), while dropout, longer windows or wider speed changes made it worse.
    draws : augmented simulations of every clip besides the benchmark's own draw.
    speed : speed changes of up to +-``speed`` (fraction) in augmented draws.
    noise_scale : noise levels scaled by up to this factor (log-uniform, both ways).
    mirror : mirror every other augmented draw left/right.
    validation : fraction of clips held out (by name hash) for the validation curve.
    dropout : dropout after the input layer and between GRU layers while training.
    weight_decay : AdamW weight decay.
    position_weight : weight of the joint-position term of the loss against the standardized
        pose-vector term (:class:`imuloco.methods.learned.train.LossWeights`).
    accel_weight : weight of the term that matches the joints' frame-to-frame accelerations
        to the ground truth's (against jitter). On held-out styles (every third clip) 150
        instead of 30 gave jitter 173 vs 198 m/s^3 and foot skate 7.2 vs 7.7 cm/s at the same
        MPJPE (3.29 vs 3.32 cm; four runs of one configuration spread over 3.18-3.32).
    lag : look-ahead in frames: the pose of frame t is output once the signals up to frame
        t + ``lag`` have been read. Offline this costs nothing; a stream's poses come ``lag``
        frames late (:attr:`LearnedStream.delay_frames`; 8 frames = 267 ms at 30 fps). On
        held-out styles (every third clip) lag 8 gave 3.29 cm against 3.52 with none (the
        lower body 2.98 vs 3.37) and less jitter and skate; lag 4 3.35, 11 3.25, 15 3.48.
    height_smooth : the root's height averaged over a centred Gaussian window of
        ``height_smooth`` frames (:func:`imuloco.methods.postprocess.gaussian_weights`; 0:
        none); a stream's poses come the window's radius, ``int(3 height_smooth + 0.5)``
        frames, later still (3 frames = 100 ms at 30 fps). The network predicts the height
        frame by frame: on held-out styles it jerked 34-57 % more than the ground truth's, and
        the whole body's jitter was 23-29 % over the ground truth's; 1.0 brings that to 7-13 %
        (seeds 0-2), and MPJPE and foot skate do not change (docs/results/learned/
        experiments.md, issue 16's jitter). Applied after training: a model file's value may
        be changed without training again.
    proportions : augmented draws are simulated on bodies of other proportions (height up to
        +-``proportions``, legs, arms and trunk a further +-half of it;
        :func:`imuloco.methods.learned.train.proportioned`), targets on the training skeleton.
    reverse : the fraction of augmented clips played backwards in time (stand-ins for walking
        backwards, :func:`imuloco.methods.learned.train.reversed_motion`). On
        ``heldout-contents`` (``--limit 30``, seed 0) 0.3 took walking backwards, never seen,
        from 10.32 to 7.43 cm (the mean pose: 10.03) and forward walking from 4.15 to 4.30.
    strap : the fraction of augmented clips whose sensor sits on a random soft-tissue strap
        (:mod:`imuloco.sensors.strap`: impacts damped, the phone rolling about the shin); a
        real shin phone rolls so at toe off (docs/results/learned/experiments.md, seventh
        round).
    incline : every augmented clip's sensors turned about their medio-lateral axis by up to
        +-``incline`` degrees (:func:`imuloco.methods.learned.train.inclined`). The calibration
        puts a real shin phone's up axis on gravity at rest, or on the walk's mean force turned
        by a prior; virtual shank sensors walk 14-29 degrees from their axis depending on the
        data set, and models trained on all motion read a real walk calibrated 12.8 degrees
        off that as a backward walk (docs/results/learned/experiments.md, diagnosis round).
    bidirectional : a GRU that reads the recording both ways (offline only: no :meth:`stream`;
        ``lag`` is then not needed and ignored).
    members : networks trained from seeds ``seed``, ``seed + 1``, ... (each with its own
        augmented draws, as separate ``train`` runs would be) and averaged (:func:`ensemble`).
        On the real shin walk four 5-epoch strap models' average walked normally where one of
        them did not (docs/results/learned/experiments.md, ninth round); their disagreement
        (``spread_m``) tells where the mean errs (fourteenth round). Costs ``members`` times
        the training and the reconstruction.
    threads : torch CPU threads while fitting, at most the machine's cores (None: torch's
        default). Use 1 on a machine shared with other jobs: torch's thread pool stalls when
        its cores are taken (a batch took 10x longer with 2 threads than with 1 on a loaded
        2-core machine).
    seed : seeds augmentation, initialization and batching.
    """

    summary = "imuloco's causal GRU: pose, contacts and confidence; feet pinned (torch)"
    # upper bounds far beyond any useful value, where a larger one only exhausted memory or
    # time or overflowed: hidden 4096 (192 by default), layers 64 (2), epochs 10^4 (20),
    # members 64 (4 in the results), threads 1024 (more than a machine's cores; 1e9 aborted
    # OpenMP), draws 100 (2: the training set 101 times over), lag 1000 frames (8; 33 s of
    # look-ahead), the loss weights 10^6 (10 and 150; 1e300 is inf in float32), weight_decay
    # 1 (1e-4: AdamW then shrinks each weight by lr a step), lr 1 (4e-3)
    param_constraints: ClassVar[dict[str, Constraint]] = {
        **dict.fromkeys(("batch_size", "window"), "[1, inf)"),
        "hidden": "[1, 4096]", "layers": "[1, 64]", "epochs": "[1, 10000]",
        "members": "[1, 64]", "threads": "[1, 1024]", "draws": "[0, 100]", "lag": "[0, 1000]",
        "height_smooth": "[0, 100]",
        "seed": "[0, inf)", "noise_scale": "[0, inf)", "weight_decay": "[0, 1]",
        **dict.fromkeys(("position_weight", "accel_weight"), "[0, 1e6]"),
        **dict.fromkeys(("speed", "validation", "dropout", "proportions"), "[0, 1)"),
        "reverse": "[0, 1]", "strap": "[0, 1]", "incline": "[0, 90]", "lr": "(0, 1]"}
    supports_online = True
    # files from before the look-ahead and the heavier acceleration term
    legacy_params: ClassVar[dict[str, Any]] = {"lag": 0, "accel_weight": 30.0,
                                               "proportions": 0.0, "bidirectional": False,
                                               "reverse": 0.0, "strap": 0.0, "members": 1,
                                               "incline": 0.0, "height_smooth": 0.0}
    # inputs centred by a causal running mean (``features="centered"``, time constant ``tau``)
    # measured worse (4.06 vs 3.94 cm, docs/results/learned/experiments.md) and were removed
    retired_params: ClassVar[dict[str, Any]] = {"features": "raw", "tau": None}

    def __init__(self, hidden: int = 192, layers: int = 2, epochs: int = 20,
                 batch_size: int = 16, window: int = 120, lr: float = 4e-3, draws: int = 2,
                 speed: float = 0.15, noise_scale: float = 2.0, mirror: bool = True,
                 validation: float = VALIDATION_SHARE, dropout: float = 0.0,
                 weight_decay: float = 1e-4, position_weight: float = 10.0,
                 accel_weight: float = 150.0, lag: int = 8,
                 height_smooth: float = 1.0,
                 proportions: float = 0.1, reverse: float = 0.3, strap: float = 0.0,
                 incline: float = 0.0, bidirectional: bool = False, members: int = 1,
                 threads: int | None = None, seed: int = 0) -> None:
        self.hidden = hidden
        self.layers = layers
        self.epochs = epochs
        self.batch_size = batch_size
        self.window = window
        self.lr = lr
        self.draws = draws
        self.speed = speed
        self.noise_scale = noise_scale
        self.mirror = mirror
        self.validation = validation
        self.dropout = dropout
        self.weight_decay = weight_decay
        self.position_weight = position_weight
        self.accel_weight = accel_weight
        self.lag = lag
        self.height_smooth = height_smooth
        self.proportions = proportions
        self.reverse = reverse
        self.strap = strap
        self.incline = incline
        self.bidirectional = bidirectional
        self.members = members
        self.threads = threads
        self.seed = seed

    # ---- learning ---------------------------------------------------------------------------
    def learn(self, data: TrainingSet, progress: bool = False) -> None:
        if self.threads:  # at most one a core: more only contend (1024 on 2 cores: a fit
            # of one epoch on 4 sample clips took over 120 s instead of 5)
            torch.set_num_threads(min(int(self.threads), os.cpu_count() or 1))
        if self.members > 1:
            one = {**self.get_params(), "members": 1}
            combined = ensemble([Learned(**{**one, "seed": self.seed + k}).fit_set(data, progress)
                                 for k in range(int(self.members))])
            self.set_state(*combined.get_state())
            return
        train_ex, val_ex = self._validation_split(data.examples)
        sk = data.skeleton
        try:
            mirror_pairs(sk)
            can_mirror = self.mirror
        except (KeyError, ValueError):
            can_mirror = False
        train_ex = tr.augment(train_ex, list(data.placements), data.noise, self.seed, self.draws,
                              self.speed, self.noise_scale, can_mirror, progress,
                              self.proportions, self.reverse, self.strap,
                              self.incline)
        train_ex = [self._looking_ahead(e) for e in train_ex]
        val_ex = [self._looking_ahead(e) for e in val_ex]
        x, y, c, pos, lengths = tr.stack(train_ex)
        self.x_mean_, self.x_std_ = x.mean(0), np.maximum(x.std(0), 1e-3)
        self.y_mean_ = y.mean(0)
        # 6-D components that barely move (end joints) would dominate a plain standardization
        self.y_std_ = np.maximum(y.std(0), 0.05)
        train_set = self._arrays(x, y, c, pos, lengths)
        val_set = self._arrays(*tr.stack(val_ex)) if val_ex else None
        self.input_map_ = np.eye(self.channels_)
        self.output_mirror_ = False
        self.frames_ = np.tile(np.eye(3), (sk.num_joints, 1, 1))
        # seeded initial weights and batches (a reproducible fit) without touching the
        # caller's global torch generator
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(self.seed)
            self.net_ = Reconstructor(x.shape[1], y.shape[1], self.hidden, self.layers,
                                      self.dropout, self.bidirectional)
            self.history_ = tr.train(self.net_, TorchFK(sk.offsets, sk.parents), train_set,
                                     val_set, self.y_mean_, self.y_std_, self.epochs,
                                     self.batch_size, self.window, self.lr,
                                     tr.LossWeights(position=self.position_weight,
                                                    accel=self.accel_weight), self.seed,
                                     progress, self.weight_decay)
        self.net_.eval()
        if not all(bool(torch.isfinite(w).all()) for w in self.net_.parameters()):
            raise InputError(f"method 'learned': the training diverged (weights became NaN or "
                             f"inf) with lr={self.lr}, weight_decay={self.weight_decay}, "
                             f"position_weight={self.position_weight}, accel_weight="
                             f"{self.accel_weight}: lower them")
        self._fit_novelty(train_set, val_set, data.fps)
        self.calibration_ = None
        self.flat_pitch_ = flat_foot_pitch(e.motion for e in data.examples)

    def _validation_split(self, examples: list[Example]) -> tuple[list[Example], list[Example]]:
        """Training and validation clips: ``validation`` of them by CRC32 of the name."""
        val = [held_out(e.labels["name"], self.validation) for e in examples]
        if all(val):
            val = [False] * len(examples)
        return ([e for e, v in zip(examples, val) if not v],
                [e for e, v in zip(examples, val) if v])

    def measure_novelty(self, data: TrainingSet) -> None:
        """Fit the novelty reference (:meth:`_fit_novelty`) of a model trained without one (a
        file from before novelty existed) on ``data``: the motions it was trained on, simulated
        the same way; clips are split into training and validation as :meth:`learn` does."""
        self.check_fitted()
        train_ex, val_ex = self._validation_split(data.examples)
        train_set = self._arrays(*tr.stack([self._looking_ahead(e) for e in train_ex]))
        val_set = (self._arrays(*tr.stack([self._looking_ahead(e) for e in val_ex]))
                   if val_ex else None)
        self._fit_novelty(train_set, val_set, data.fps)

    @property
    def channels_(self) -> int:
        """Sensor channels (6 per sensor) the model reads."""
        return int(self.x_mean_.shape[0])

    @property
    def lookahead(self) -> int:
        """The look-ahead in use: ``lag``, none for a bidirectional model."""
        return 0 if self.bidirectional else int(self.lag)

    @property
    def height_weights(self) -> np.ndarray:
        """The window the root's height is averaged over (:attr:`height_smooth`)."""
        return gaussian_weights(float(self.height_smooth))

    def _looking_ahead(self, e: Example) -> Example:
        """Training inputs: row t holds the signals of frame t + ``lookahead`` (the last frame's
        repeated past the end), the look-ahead the network learns to use."""
        s = _hold_last(np.nan_to_num(e.signals), self.lookahead)[self.lookahead:]
        return Example(e.motion, s, e.labels)


    def _arrays(self, x: np.ndarray, y: np.ndarray, c: np.ndarray, pos: np.ndarray,
                lengths: np.ndarray) -> tr.Arrays:
        starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
        return tr.Arrays(((x - self.x_mean_) / self.x_std_).astype(np.float32),
                         ((y - self.y_mean_) / self.y_std_).astype(np.float32), c, pos,
                         starts, lengths)

    # ---- reconstruction ---------------------------------------------------------------------
    def _inputs(self, signals: np.ndarray) -> torch.Tensor:
        """Standardized network inputs of signals (T, 6 S) in this leg's sensor axes."""
        s = np.nan_to_num(np.asarray(signals, dtype=np.float64)) @ self.input_map_.T
        return torch.as_tensor((s - self.x_mean_) / self.x_std_, dtype=torch.float32)

    def _heads(self, feats: torch.Tensor
               ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor | None]:
        """The heads' pose, contact logits and logvar of features (B, T, W), and an ensemble's
        members' standardized poses (B, T, K, D) (None for one network)."""
        if not isinstance(self.net_, Ensemble):
            return (*self.net_.heads(feats), None)
        poses, logit, logvar = self.net_.member_heads(feats)
        return poses.mean(-2), logit, logvar, poses

    def _outputs(self, p: torch.Tensor, logit: torch.Tensor, logvar: torch.Tensor,
                 novelty: np.ndarray, members: torch.Tensor | None = None) -> Prediction:
        vectors = p.numpy().astype(np.float64) * self.y_std_ + self.y_mean_
        contacts = torch.sigmoid(logit).numpy().astype(np.float64)
        if self.output_mirror_:
            vectors, contacts = self._mirror_vectors(vectors), contacts[..., CONTACT_SWAP]
        sigma = np.exp(0.5 * logvar.numpy()[..., 0].astype(np.float64))
        spread = None if members is None else member_spread(  # a mirror keeps distances
            members.numpy().astype(np.float64) * self.y_std_ + self.y_mean_, self.skeleton_)
        return Prediction(vectors, contacts, sigma, novelty, spread)

    def predict(self, signals: np.ndarray, ahead: int = 0) -> Prediction:
        """Network outputs for signals (T, 6 S) at the model rate, run from a zero state; and
        for ``ahead`` frames past the end, the last sample held (as a stream is fed to give
        its last frames; a network reading both ways: must be 0)."""
        signals = np.asarray(signals)
        if signals.ndim != 2 or signals.shape[1] != self.channels_:
            raise ValueError(f"learned: expected signals (T, {self.channels_}) for "
                             f"placements {self.placements_}, got {signals.shape}")
        if ahead and self.bidirectional:
            raise ValueError("learned: a network reading both ways has no frames past the end")
        k = self.lookahead
        signals = _hold_last(signals, k + ahead)  # as a stream would be fed to get every frame
        with torch.no_grad():
            feats, _ = self.net_.encode(self._inputs(signals)[None])
            p, logit, logvar, members = self._heads(feats)
        novelty = self._novelty(feats[0].numpy())  # float64 a piece at a time
        return self._outputs(p[0, k:], logit[0, k:], logvar[0, k:], novelty[k:],
                             None if members is None else members[0, k:])

    def reconstruct_signals(self, signals: np.ndarray) -> Motion:
        return self.reconstruct_signals_full(signals).motion

    def pose_vectors(self, signals: np.ndarray) -> tuple[Prediction, np.ndarray]:
        """:meth:`predict`'s outputs for ``signals`` (T, 6 S), and the pose vectors
        (T, 6 J + 4) to decode: the root's height averaged over :attr:`height_weights`, which
        read the frames past the end as a stream does (its last sample held)."""
        w = self.height_weights
        ahead = 0 if self.bidirectional else len(w) // 2
        full = self.predict(signals, ahead)
        out = full.first(len(signals))
        vectors = out.vectors.copy()
        h = pose.height_index(self.skeleton_)
        vectors[:, h] = window_average(full.vectors[:, h], w, ahead)
        return out, vectors

    def reconstruct_signals_full(self, signals: np.ndarray) -> Reconstruction:
        out, vectors = self.pose_vectors(signals)
        motion = lock(pin(pose.decode(vectors, self.skeleton_, self.fps_), out.contacts),
                      out.contacts, self.flat_pitch_)
        err, flag, note = self.confidence(out)
        return Reconstruction(motion, err, flag, note, out.scores())

    def can_stream(self) -> bool:
        """Online unless the network reads the recording both ways (``bidirectional``)."""
        return not self.bidirectional

    def stream(self) -> LearnedStream:
        if self.bidirectional:
            raise NotImplementedError(
                "this learned model reads the recording both ways (bidirectional=True): it "
                "reconstructs offline only; use a causal model (bidirectional=False) online")
        return LearnedStream(self)

    @property
    def pins_feet(self) -> bool:
        """Always: the feet are pinned on the contacts the network predicts."""
        return True

    @property
    def novelty_threshold(self) -> float | None:
        """The flag threshold of its novelty (:meth:`_fit_novelty`: the 99 % quantile on
        held-out training motion; None for a file from before novelty was measured)."""
        return None if self.novelty_mean_ is None else self.novelty_threshold_

    # ---- the other leg ----------------------------------------------------------------------

    def write_training_report(self, model_path: str | Path) -> list[Path]:
        """The per-epoch losses as MODEL.history.json and, with matplotlib, MODEL.curves.png."""
        model_path = Path(model_path)
        if not self.history_:
            return []
        out = model_path.with_name(model_path.name + ".history.json")
        out.write_text(json.dumps(self.history_, indent=1))
        png = tr.plot_history(self.history_, model_path.with_name(model_path.name + ".curves.png"))
        return [out] + ([png] if png is not None else [])

    # ---- persistence ------------------------------------------------------------------------
    def get_state(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        arrays = {f"net.{k}": v.detach().numpy().copy() for k, v in
                  self.net_.state_dict().items()}
        arrays.update(x_mean=self.x_mean_, x_std=self.x_std_, y_mean=self.y_mean_,
                      y_std=self.y_std_, input_map=self.input_map_, frames=self.frames_)
        values = {"output_mirror": bool(self.output_mirror_), "history": self.history_,
                  "channels": int(self.x_mean_.shape[0]), "pose_dim": int(self.y_mean_.shape[0]),
                  "calibration": self.calibration_}
        if self.flat_pitch_ is not None:
            values.update(flat_pitch=self.flat_pitch_)
        if self.novelty_mean_ is not None:
            arrays.update(novelty_mean=self.novelty_mean_,
                          novelty_precision=self.novelty_precision_)
            values.update(novelty_alpha=self.novelty_alpha_, novelty_scale=self.novelty_scale_,
                          novelty_threshold=self.novelty_threshold_)
        return arrays, values

    def set_state(self, arrays: dict[str, np.ndarray], values: dict[str, Any]) -> None:
        self.x_mean_, self.x_std_ = arrays["x_mean"], arrays["x_std"]
        self.y_mean_, self.y_std_ = arrays["y_mean"], arrays["y_std"]
        self.input_map_, self.frames_ = arrays["input_map"], arrays["frames"]
        self.output_mirror_ = bool(values["output_mirror"])
        self.history_ = values.get("history", [])
        if "protocol" in values:  # files from before the base class saved the protocol
            self.protocol_ = values["protocol"]
        self.calibration_ = values.get("calibration")
        # None: a file from before (the lock holds a flat foot at the pitch it lands with)
        pitch = values.get("flat_pitch")
        if pitch is not None and not (isinstance(pitch, (int, float))
                                      and abs(pitch) <= np.pi / 2):
            raise ValueError(f"flat_pitch: expected an angle in radians within +-pi/2, "
                             f"got {pitch!r}")
        self.flat_pitch_ = None if pitch is None else float(pitch)
        self.novelty_mean_ = arrays.get("novelty_mean")  # None: a file from before novelty
        if self.novelty_mean_ is not None:
            self.novelty_precision_ = arrays["novelty_precision"]
            self.novelty_alpha_ = float(values["novelty_alpha"])
            self.novelty_scale_ = float(values["novelty_scale"])
            self.novelty_threshold_ = float(values["novelty_threshold"])
        shape = {"channels": int(values["channels"]), "pose_dim": int(values["pose_dim"]),
                 "hidden": self.hidden, "layers": self.layers, "dropout": self.dropout,
                 "bidirectional": self.bidirectional}
        self.net_ = (Ensemble.of_size(int(self.members), **shape) if self.members > 1
                     else Reconstructor(**shape))
        self.net_.load_state_dict({k[4:]: torch.as_tensor(arrays[k]) for k in arrays
                                   if k.startswith("net.")})
        self.net_.eval()


def _hold_last(s: np.ndarray, n: int) -> np.ndarray:
    """``s`` (T, C) followed by its last row ``n`` more times: the look-ahead's input past the
    end of a recording."""
    return np.concatenate([s, np.repeat(s[-1:], n, axis=0)])
