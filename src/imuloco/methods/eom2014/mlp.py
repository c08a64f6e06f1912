"""Regressions from sensor features to latent points, Eom et al. 2014 sec. 5.5 and Fig. 8.

:func:`fit_mlp` trains scikit-learn's MLPRegressor (the paper used ALGLIB's MLP, size not
given) and keeps only its weights; :func:`predict` evaluates them in numpy, so a saved model
holds plain arrays (no pickled estimator). :func:`fit_linear` is the "linear regression to the
latent space" of the ablation (Fig. 8, second row).
"""

from __future__ import annotations

import warnings

import numpy as np
from sklearn.exceptions import ConvergenceWarning
from sklearn.neural_network import MLPRegressor


def fit_mlp(features: np.ndarray, targets: np.ndarray, hidden: tuple[int, ...] = (32,),
            max_iter: int = 200, seed: int = 0, max_samples: int = 20000) -> list[np.ndarray]:
    """Train an MLP (tanh hidden layers, linear output) on standardized inputs and outputs.

    features : ndarray, shape (N, f); targets : ndarray, shape (N, q).
    max_samples : at most this many rows (an even subsample) train the network.
    Returns the parameter list ``[x_mean, x_std, y_mean, y_std, W1, b1, W2, b2, ...]``.
    """
    features, targets = np.asarray(features, np.float64), np.asarray(targets, np.float64)
    if len(features) > max_samples:
        idx = np.linspace(0, len(features) - 1, max_samples).astype(np.int64)
        features, targets = features[idx], targets[idx]
    xm, xs = features.mean(0), features.std(0) + 1e-8
    ym, ys = targets.mean(0), targets.std(0) + 1e-8
    net = MLPRegressor(hidden_layer_sizes=tuple(hidden), activation="tanh", max_iter=max_iter,
                       early_stopping=len(features) >= 50, random_state=seed,
                       learning_rate_init=3e-3, alpha=1e-4)
    with warnings.catch_warnings():  # a capped iteration count is a choice, not an error
        warnings.simplefilter("ignore", ConvergenceWarning)
        net.fit((features - xm) / xs, (targets - ym) / ys)
    params = [xm, xs, ym, ys]
    for w, b in zip(net.coefs_, net.intercepts_):
        params += [w, b]
    return params


def fit_linear(features: np.ndarray, targets: np.ndarray, ridge: float = 1e-6
               ) -> list[np.ndarray]:
    """Least squares (tiny ridge) from features (N, f) to targets (N, q), in the same
    parameter layout as :func:`fit_mlp` with no hidden layer."""
    features, targets = np.asarray(features, np.float64), np.asarray(targets, np.float64)
    xm, xs = features.mean(0), features.std(0) + 1e-8
    ym, ys = targets.mean(0), targets.std(0) + 1e-8
    a = (features - xm) / xs
    w = np.linalg.solve(a.T @ a + ridge * len(a) * np.eye(a.shape[1]), a.T @ ((targets - ym) / ys))
    return [xm, xs, ym, ys, w, np.zeros(w.shape[1])]


def predict(params: list[np.ndarray], features: np.ndarray) -> np.ndarray:
    """Evaluate :func:`fit_mlp` / :func:`fit_linear` parameters. features : (..., f) ->
    (..., q)."""
    xm, xs, ym, ys = params[:4]
    h = (np.asarray(features, np.float64) - xm) / xs
    layers = params[4:]
    for i in range(0, len(layers), 2):
        h = h @ layers[i] + layers[i + 1]
        if i + 2 < len(layers):
            h = np.tanh(h)
    return h * ys + ym
