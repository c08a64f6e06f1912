"""Floors every method must beat: the mean pose, a ridge regression and a kNN lookup.

``ridge`` and ``knn`` map a causal window of sensor samples (:func:`imuloco.methods.features.
windows`, ending at the current frame) to a pose vector (:mod:`imuloco.methods.pose`), so their
offline reconstruction and their online stream give the same frames.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np
from sklearn.linear_model import Ridge
from sklearn.neighbors import NearestNeighbors

from imuloco.core.motion import Motion
from imuloco.methods import pose
from imuloco.methods.base import Method, Stream
from imuloco.methods.features import (
    PoseIntegrator,
    WindowBuffer,
    fit_standardizer,
    standardize,
    windows,
)
from imuloco.methods.params import Constraint
from imuloco.methods.training import Example, TrainingSet


class _ConstantStream(Stream):
    """The mean pose vector every frame, integrated like :func:`pose.decode` (same frames as
    the offline reconstruction)."""

    def __init__(self, method: MeanPose) -> None:
        self.vector = method.mean_
        self.integrator = PoseIntegrator(method.skeleton_, method.fps_)

    def step(self, sample: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.integrator.step(self.vector)


class MeanPose(Method):
    """The mean pose vector of the training data, whatever the sensors read (a standing
    figure that walks at the mean speed)."""

    summary = "mean training pose, ignores the sensors (a floor for every metric)"
    supports_online = True

    def __init__(self) -> None:
        pass

    def learn(self, data: TrainingSet, progress: bool = False) -> None:
        self.mean_ = np.concatenate([pose.encode(e.motion) for e in data.examples]).mean(axis=0)

    def reconstruct_signals(self, signals: np.ndarray) -> Motion:
        return pose.decode(np.tile(self.mean_, (len(signals), 1)), self.skeleton_, self.fps_)

    def stream(self) -> Stream:
        return _ConstantStream(self)

    def get_state(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        return {"mean": self.mean_}, {}

    def set_state(self, arrays: dict[str, np.ndarray], values: dict[str, Any]) -> None:
        self.mean_ = arrays["mean"]


# samples per causal window: 1000 is 33 s at 30 fps (8 s at 120), many strides; a row holds
# window x 6 S features (window=1e5 asked 1.1 GiB per sample clip and ran out of memory)
WINDOW_RANGE = "[1, 1000]"


def _training_arrays(examples: Sequence[Example], window: int) -> tuple[np.ndarray, np.ndarray]:
    """Causal windows of every clip's signals (N, window * 6S) and its pose vectors (N, D)."""
    x = np.concatenate([windows(e.signals, window) for e in examples])
    y = np.concatenate([pose.encode(e.motion) for e in examples])
    return x, y


class _WindowedStream(Stream):
    """Online stream of a windowed regressor: window -> pose vector -> integrated frame."""

    def __init__(self, method: _Windowed) -> None:
        self.method = method
        self.buffer = WindowBuffer(method.window)
        self.integrator = PoseIntegrator(method.skeleton_, method.fps_)

    def step(self, sample: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        row = self.buffer.push(sample)[None]
        return self.integrator.step(self.method._predict(row)[0])


class _Windowed(Method):
    """Shared parts of the windowed regressors: features, decoding, streaming."""

    window: int
    supports_online = True

    def _features(self, signals: np.ndarray) -> np.ndarray:
        return standardize(windows(signals, self.window), self.x_mean_, self.x_scale_)

    def _predict(self, windowed: np.ndarray) -> np.ndarray:
        """Raw (unstandardized) window rows (N, window*6S) -> pose vectors (N, 6J+4)."""
        raise NotImplementedError

    def reconstruct_signals(self, signals: np.ndarray) -> Motion:
        signals = np.asarray(signals, dtype=np.float64)
        return pose.decode(self._predict(windows(signals, self.window)), self.skeleton_,
                           self.fps_)

    def stream(self) -> Stream:
        return _WindowedStream(self)


class RidgePose(_Windowed):
    """Direct linear regression from a window of sensor samples to the full pose vector, the
    "Simple Linear Regression" of Eom et al. 2014 sec. 7 (Fig. 8, first row), with an L2
    penalty (scikit-learn ``Ridge``) on standardized inputs and outputs."""

    summary = "ridge regression from a causal window of sensor samples to the pose (2014 Fig. 8)"
    param_constraints: ClassVar[dict[str, Constraint]] = {"window": WINDOW_RANGE, "alpha": "[0, inf)"}

    def __init__(self, window: int = 15, alpha: float = 1.0) -> None:
        self.window = window  # samples per causal window (0.5 s at 30 fps); not in the paper
        self.alpha = alpha  # L2 penalty on standardized features; the paper uses none

    def learn(self, data: TrainingSet, progress: bool = False) -> None:
        x, y = _training_arrays(data.examples, self.window)
        self.x_mean_, self.x_scale_ = fit_standardizer(x)
        self.y_mean_, self.y_scale_ = fit_standardizer(y)
        model = Ridge(alpha=self.alpha).fit(standardize(x, self.x_mean_, self.x_scale_),
                                            standardize(y, self.y_mean_, self.y_scale_))
        self.coef_, self.intercept_ = model.coef_, model.intercept_

    def _predict(self, windowed: np.ndarray) -> np.ndarray:
        z = standardize(windowed, self.x_mean_, self.x_scale_) @ self.coef_.T + self.intercept_
        return z * self.y_scale_ + self.y_mean_

    def get_state(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        return {k: getattr(self, k + "_") for k in
                ("x_mean", "x_scale", "y_mean", "y_scale", "coef", "intercept")}, {}

    def set_state(self, arrays: dict[str, np.ndarray], values: dict[str, Any]) -> None:
        for k in ("x_mean", "x_scale", "y_mean", "y_scale", "coef", "intercept"):
            setattr(self, k + "_", arrays[k])


class KnnPose(_Windowed):
    """Windowed k-nearest-neighbour pose lookup: the training frames whose causal windows of
    standardized sensor samples are closest (Euclidean) to the input's give the pose, as the
    inverse-distance weighted mean of their pose vectors (scikit-learn ``NearestNeighbors``).
    Training rows are kept every ``stride`` frames to bound the model's size."""

    summary = "k-nearest-neighbour lookup of poses by a causal window of sensor samples"
    param_constraints: ClassVar[dict[str, Constraint]] = {"window": WINDOW_RANGE, "k": "[1, inf)",
                                              "stride": "[1, inf)"}

    def __init__(self, window: int = 15, k: int = 8, stride: int = 1) -> None:
        self.window = window  # samples per causal window (0.5 s at 30 fps)
        self.k = k  # neighbours averaged
        self.stride = stride  # keep every stride-th training frame

    def learn(self, data: TrainingSet, progress: bool = False) -> None:
        x, y = _training_arrays(data.examples, self.window)
        x, y = x[:: self.stride], y[:: self.stride]
        self.x_mean_, self.x_scale_ = fit_standardizer(x)
        self.features_ = standardize(x, self.x_mean_, self.x_scale_).astype(np.float32)
        self.poses_ = y.astype(np.float32)
        self._build()

    def _build(self) -> None:
        self._k = min(self.k, len(self.features_))
        self._f = self.features_.astype(np.float64)
        self._sq = (self._f**2).sum(axis=1)
        self._nn = NearestNeighbors(n_neighbors=self._k, algorithm="brute").fit(self._f)

    def _neighbours(self, q: np.ndarray) -> np.ndarray:
        """Indices (N, k) of the nearest training windows of standardized rows q (N, F).

        Batches go to scikit-learn; a few rows (the online stream) use one matrix-vector
        product, because scikit-learn's per-call overhead (input checks, an OpenMP pool) is
        10-100 ms on a busy machine, against about 1 ms for the product itself. Both rank by
        the same Euclidean distance; they can differ only on exact float ties.
        """
        if len(q) > 4:
            return self._nn.kneighbors(q, return_distance=False)
        d2 = self._sq[None] - 2.0 * q @ self._f.T  # + |q|^2, the same for every candidate
        idx = np.argpartition(d2, self._k - 1, axis=1)[:, : self._k]
        return np.take_along_axis(idx, np.argsort(np.take_along_axis(d2, idx, 1), 1), 1)

    def _predict(self, windowed: np.ndarray) -> np.ndarray:
        q = standardize(windowed, self.x_mean_, self.x_scale_)
        idx = self._neighbours(q)
        dist = np.linalg.norm(self._f[idx] - q[:, None], axis=-1)  # exact, for the weights
        order = np.argsort(dist, axis=1, kind="stable")
        idx, dist = np.take_along_axis(idx, order, 1), np.take_along_axis(dist, order, 1)
        w = 1.0 / (dist + 1e-6)
        w /= w.sum(axis=1, keepdims=True)
        return np.einsum("nk,nkd->nd", w, self.poses_[idx].astype(np.float64))

    def get_state(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        return {"x_mean": self.x_mean_, "x_scale": self.x_scale_, "features": self.features_,
                "poses": self.poses_}, {}

    def set_state(self, arrays: dict[str, np.ndarray], values: dict[str, Any]) -> None:
        self.x_mean_, self.x_scale_ = arrays["x_mean"], arrays["x_scale"]
        self.features_, self.poses_ = arrays["features"], arrays["poses"]
        self._build()
