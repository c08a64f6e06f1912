"""``learned``'s confidence: the network's features' novelty against its training data's
(:meth:`ConfidenceMixin._fit_novelty`), and the predicted error and unreliable flags a
:class:`Prediction`'s scores give (:meth:`ConfidenceMixin.confidence`, calibrated by
``imuloco calibrate``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from scipy.signal import lfilter

from imuloco.errors import InputError
from imuloco.methods.base import calibrated_error
from imuloco.methods.learned import train as tr
from imuloco.methods.learned.model import Ensemble

# the uncalibrated per-frame scores a calibration maps; the last, an ensemble's only
SCORES = ("novelty", "sigma_m", "spread_m")
NOVELTY_TAU_S = 1.0  # time constant (s) of the causal smoothing of the novelty
FLAG_QUANTILE = 0.99  # frames above this quantile of held-out training-motion novelty: flagged


@dataclass
class Prediction:
    """Per-frame outputs of the network, decoded.

    vectors : ndarray, shape (T, 6 J + 4), pose vectors (:mod:`imuloco.methods.pose`).
    contacts : ndarray, shape (T, 4), contact probabilities of
        :data:`imuloco.methods.learned.model.CONTACT_PARTS`.
    sigma : ndarray, shape (T,), the network's predicted rms joint position error, metres.
    novelty : ndarray, shape (T,), how unfamiliar the frame's features are (about 1 on the
        motions the model was trained on; :meth:`Learned._fit_novelty`).
    spread : ndarray, shape (T,), an ensemble's members' disagreement, metres
        (:func:`member_spread`); None for one network.
    """

    vectors: np.ndarray
    contacts: np.ndarray
    sigma: np.ndarray
    novelty: np.ndarray
    spread: np.ndarray | None = None

    def first(self, n: int) -> Prediction:
        """The first ``n`` frames."""
        return Prediction(self.vectors[:n], self.contacts[:n], self.sigma[:n],
                          self.novelty[:n], None if self.spread is None else self.spread[:n])

    def scores(self) -> dict[str, np.ndarray]:
        """The uncalibrated per-frame scores a calibration maps, by name (:data:`SCORES`)."""
        out = {"sigma_m": self.sigma, "novelty": self.novelty}
        return out if self.spread is None else {**out, "spread_m": self.spread}


NOVELTY_FRAMES = 2048  # frames a piece of the novelty's distances


class ConfidenceMixin:
    """The confidence part of :class:`~imuloco.methods.learned.method.Learned`."""

    def _clip_features(self, arrays: tr.Arrays, max_clips: int = 400) -> list[np.ndarray]:
        """The network's features (:meth:`Reconstructor.encode`) of up to ``max_clips`` clips
        of ``arrays`` (evenly spaced), each run from a zero state."""
        pick = np.unique(np.linspace(0, len(arrays.starts) - 1,
                                     min(max_clips, len(arrays.starts))).astype(int))
        out = []
        with torch.no_grad():
            for i in pick:
                s, n = int(arrays.starts[i]), int(arrays.lengths[i])
                out.append(self.net_.encode(torch.from_numpy(arrays.x[s:s + n])[None])[0][0]
                           .numpy().astype(np.float64))
        return out

    def _fit_novelty(self, train_set: tr.Arrays, val_set: tr.Arrays | None, fps: float) -> None:
        """How far a frame's features lie from the training data's: a Mahalanobis distance
        (the feature-space detector of unfamiliar inputs of Lee et al. 2018) under a
        Ledoit-Wolf covariance of training features, per feature, smoothed causally
        (:data:`NOVELTY_TAU_S`) and divided by its median on the validation clips (held-out
        clips of the training motions; the training clips when there are none). Frames above
        its :data:`FLAG_QUANTILE` quantile there are flagged unreliable."""
        # scikit-learn, and the pandas it imports, only for training: a reconstruction that
        # loads a fitted model holds ~65 MB less and starts ~2 s sooner (issue 43)
        from sklearn.covariance import LedoitWolf

        feats = np.concatenate(self._clip_features(train_set))
        rows = np.random.default_rng(self.seed).permutation(len(feats))[:20000]
        lw = LedoitWolf().fit(feats[rows])
        self.novelty_mean_, self.novelty_precision_ = lw.location_, lw.precision_
        self.novelty_alpha_ = 1.0 / (NOVELTY_TAU_S * fps)
        self.novelty_scale_ = 1.0
        ref = val_set if val_set is not None and len(val_set.starts) else train_set
        nov = np.concatenate([self._novelty(f) for f in self._clip_features(ref)])
        self.novelty_scale_ = float(np.median(nov))
        self.novelty_threshold_ = float(np.quantile(nov, FLAG_QUANTILE) / self.novelty_scale_)

    def _novelty(self, feats: np.ndarray, state: float | None = None) -> np.ndarray:
        """Smoothed, scaled novelty (T,) of features (T, W) (NaN for a model file from before
        novelty was measured); ``state``: the last value of a stream's previous frames."""
        if self.novelty_mean_ is None:
            return np.full(len(feats), np.nan)
        # frame by frame alike: a long recording's frames NOVELTY_FRAMES at a time, in float64
        # (a 640 s walk's 4 x 192 features in one go held ~0.5 GB of float64 products)
        d2 = np.concatenate([self._distance(feats[i:i + NOVELTY_FRAMES])
                             for i in range(0, len(feats), NOVELTY_FRAMES)])
        a = self.novelty_alpha_
        prev = d2[0] if state is None else state * self.novelty_scale_
        if len(d2) == 1:  # a stream's step: the recursion below, without lfilter's overhead
            return np.array([(a * d2[0] + (1 - a) * prev) / self.novelty_scale_])
        zi = np.array([(1 - a) * prev])
        return lfilter([a], [1, -(1 - a)], d2, zi=zi)[0] / self.novelty_scale_

    def _distance(self, feats: np.ndarray) -> np.ndarray:
        """The squared Mahalanobis distance (T,) of features (T, W) to the training features,
        over the feature count."""
        p = self.novelty_precision_
        p = p if p.ndim == 3 else p[None]  # an ensemble's: one block per member
        feats = np.asarray(feats, dtype=np.float64)
        d = (feats - self.novelty_mean_).reshape(len(feats), len(p), -1).transpose(1, 0, 2)
        # one product per member block (K, T, W) @ (K, W, W): a stream's step is a (1, W) row
        # per block, which numpy's BLAS runs on one thread (over the side-by-side features, a
        # (1, K W) @ (K W, K W) product took its threads and made a step 6 ms slower on a busy
        # 2-core machine); np.einsum's own loops took 7 times as long a step, 17 offline
        return ((d @ p) * d).sum((0, 2)) / (d.shape[0] * d.shape[2])

    def set_calibration(self, calibration: dict[str, Any]) -> None:
        self.check_fitted()
        names = list(calibration.get("scores", []))
        known = self.score_names
        if (not names or len(set(names)) != len(names) or set(names) - set(known)
                or len(calibration.get("coef", [])) != len(names) + 1):
            raise InputError(f"learned: a calibration must map some of this model's scores "
                             f"{list(known)} (coef a, then one exponent each), got {calibration}"
                             + ("" if "spread_m" in known else "; spread_m needs an ensemble"))
        self.calibration_ = dict(calibration)

    @property
    def score_names(self) -> tuple[str, ...]:
        """The per-frame scores this model gives (:data:`SCORES`; ``spread_m``: ensembles)."""
        return SCORES if isinstance(self.net_, Ensemble) else SCORES[:2]

    def confidence(self, out: Prediction) -> tuple[np.ndarray, np.ndarray | None, str]:
        """Predicted rms joint position error (T,) in metres, unreliable flags (T,) and a
        note, from a prediction's scores (:meth:`Prediction.scores`; see
        :attr:`calibration_`); the flags from the novelty alone."""
        flag = None if self.novelty_mean_ is None else out.novelty > self.novelty_threshold_
        why = ("no frames flagged (a model file from before novelty was measured)"
               if flag is None else "frames flagged where the features are farther from the "
               f"training data than {FLAG_QUANTILE:.0%} of held-out training-motion frames'")
        cal = self.calibration_
        if cal is None:
            return out.sigma, flag, "error_m: the network's own estimate, not calibrated; " + why
        err = calibrated_error(cal, out.scores())
        return err, flag, f"error_m calibrated on {cal['source']}; " + why
