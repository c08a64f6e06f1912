"""GPLVM with per-channel scaling and a velocity GP, Eom et al. 2014 sec. 5.1-5.3 and 6.2.

Hand-written because no installed library has this model: GPy is absent, and the velocity GP's
kernel (eq. 3, after Levine et al. 2012) and the joint MAP objective (eq. 6) are specific.

Objective (maximized; we minimize its negative with L-BFGS-B and analytic gradients):

    L = L_Y + L_Ydot + ln p(alpha) + ln p(beta)                                  (eq. 6)
    L_Y = -1/2 tr(K_Y^-1 Y W^2 Y^T) - d_y/2 ln|K_Y| + N ln|W|                    (eq. 2)
    L_Ydot = -1/2 tr(K_V^-1 Ydot W_V^2 Ydot^T) - d_v/2 ln|K_V| + M ln|W_V|       (eq. 4)
    k_Y(x_i, x_j) = a1 exp(-a2/2 |x_i - x_j|^2) + a3 delta_ij                   (eq. 1)
    k_V = b1 xd_i.xd_j exp(-b2/2 |xd_i - xd_j|^2 - b3/2 |x_i - x_j|^2) + b4 delta_ij  (eq. 3)
    ln p(alpha) = -sum ln a_i,  ln p(beta) = -sum ln b_i

with ``xd_i = x_i - x_{i-1}`` and Y, Ydot centred by their column means (the "bias" of eq. 7).
``M`` is the number of velocity samples (the paper writes N for both terms).

Choices where the paper is silent:

- X gets the unit Gaussian prior of the GPLVM the paper builds on (Lawrence 2005), weight
  ``x_prior``: eq. 6 leaves it out, but then the prior -ln a2 rewards spreading X without
  bound (x -> c x, a2 -> a2 / c^2 leaves eq. 2 unchanged). ``x_prior=0`` is eq. 6 as printed.
- Parameters are optimized in log space (``ln a, ln b, ln w``), positivity for free.
- ``a1`` and ``b1`` are fixed to 1: K -> cK, W -> sqrt(c) W leaves eq. 2 unchanged, so with
  the 1/a prior the posterior grows without bound as c -> 0; W already carries the output scale
  (as in Grochow et al. 2004, whose W the paper cites). The other log-parameters are boxed
  (:data:`BOUNDS`) for the same reason (a3 -> 0 is rewarded by its prior).
- Initialisation: X from PCA of the W-scaled centred poses (W_k = 1 / std of channel k), scaled
  to unit variance along the first axis; a2 = 1, a3 = 0.01, b2 = 1 / mean |xd|^2, b3 = 1,
  b4 = 0.01, W_V from the velocity channels' stds.
- The pose mean of eq. 7 is written ``W Y^T K^-1 k + bias``; with Y scaled by W for learning
  the prediction in the original units is ``Y^T K^-1 k + bias`` (the W cancels), used here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import cho_factor, cho_solve
from scipy.linalg.lapack import dpotrf, dpotri
from scipy.optimize import minimize

# log-parameter boxes for L-BFGS-B: (ln a1, ln a2, ln a3), (ln b1, ..., ln b4); a1, b1 fixed.
BOUNDS_ALPHA = ((0.0, 0.0), (np.log(1e-3), np.log(1e3)), (np.log(1e-5), np.log(10.0)))
BOUNDS_BETA = ((0.0, 0.0), (np.log(1e-4), np.log(1e4)), (np.log(1e-3), np.log(1e3)),
               (np.log(1e-5), np.log(10.0)))
JITTER = 1e-8


def sqdist(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Squared Euclidean distances. a : (N, q), b : (M, q) -> (N, M)."""
    d = (a * a).sum(1)[:, None] + (b * b).sum(1)[None, :] - 2.0 * a @ b.T
    return np.maximum(d, 0.0)


def rbf_kernel(xa: np.ndarray, xb: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Eq. 1 without the noise term: a1 exp(-a2/2 |xa - xb|^2). xa : (N, q), xb : (M, q)."""
    return alpha[0] * np.exp(-0.5 * alpha[1] * sqdist(xa, xb))


def velocity_kernel(pa: np.ndarray, va: np.ndarray, pb: np.ndarray, vb: np.ndarray,
                    beta: np.ndarray) -> np.ndarray:
    """Eq. 3 without the noise term. pa, va : (N, q) latent points and their velocities
    ``x_i - x_{i-1}``; pb, vb : (M, q) -> (N, M)."""
    return beta[0] * (va @ vb.T) * np.exp(-0.5 * beta[1] * sqdist(va, vb)
                                          - 0.5 * beta[2] * sqdist(pa, pb))


def _gp_term(k: np.ndarray, y: np.ndarray, w: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """One GP likelihood (eq. 2 or 4) and its gradients.

    k : (N, N) kernel matrix incl. noise; y : (N, d) centred data; w : (d,) scales.
    Returns L, dL/dK (N, N), dL/d ln w (d,).
    """
    n, d = y.shape
    # LAPACK potrf/potri: one Cholesky gives ln|K| and K^-1 (cho_solve with the identity is
    # several times slower)
    chol, info = dpotrf(k + JITTER * np.eye(n), lower=1)
    if info != 0:
        raise np.linalg.LinAlgError("GP kernel matrix is not positive definite")
    kinv, _ = dpotri(chol, lower=1)
    kinv = np.tril(kinv) + np.tril(kinv, -1).T
    yw = y * w
    b = kinv @ yw                                            # K^-1 Y W
    logdet = 2.0 * np.log(np.diag(chol)).sum()
    quad = (yw * b).sum(0)                                   # w_k^2 y_k^T K^-1 y_k
    value = -0.5 * quad.sum() - 0.5 * d * logdet + n * np.log(w).sum()
    g = 0.5 * (b @ b.T) - 0.5 * d * kinv
    return value, g, n - quad


def _unpack(theta: np.ndarray, n: int, q: int, dy: int, dv: int):
    x = theta[: n * q].reshape(n, q)
    o = n * q
    la, lb = theta[o:o + 3], theta[o + 3:o + 7]
    lw = theta[o + 7:o + 7 + dy]
    lwv = theta[o + 7 + dy:o + 7 + dy + dv]
    return x, la, lb, lw, lwv


def neg_log_posterior(theta: np.ndarray, y: np.ndarray, ydot: np.ndarray, cur: np.ndarray,
                      prev: np.ndarray, q: int, x_prior: float = 1.0) -> tuple[float, np.ndarray]:
    """Minus eq. 6 and its gradient.

    Parameters
    ----------
    theta : ndarray, shape (N q + 7 + d_y + d_v,): X (row-major), ln alpha (3), ln beta (4),
        ln W (d_y), ln W_V (d_v).
    y : ndarray, shape (N, d_y), centred poses.
    ydot : ndarray, shape (M, d_v), centred velocities of the pairs ``(prev[m], cur[m])``.
    cur, prev : ndarray, shape (M,), int: frame indices of each velocity sample.
    q : latent dimension.
    x_prior : weight of the GPLVM's unit Gaussian prior on X, ``-x_prior/2 |X|^2``.
    """
    n, dy = y.shape
    dv = ydot.shape[1]
    x, la, lb, lw, lwv = _unpack(theta, n, q, dy, dv)
    alpha, beta, w, wv = np.exp(la), np.exp(lb), np.exp(lw), np.exp(lwv)

    # pose GP (eq. 1-2)
    e = rbf_kernel(x, x, alpha)
    ly, g, gw = _gp_term(e + alpha[2] * np.eye(n), y, w)
    m = g * e
    gx = -2.0 * alpha[1] * (m.sum(1)[:, None] * x - m @ x)
    ga = np.array([(m).sum(), -0.5 * (m * sqdist(x, x)).sum() * alpha[1],
                   np.trace(g) * alpha[2]])

    # velocity GP (eq. 3-4)
    p, v = x[cur], x[cur] - x[prev]
    dvv, dpp = sqdist(v, v), sqdist(p, p)
    ev = np.exp(-0.5 * beta[1] * dvv - 0.5 * beta[2] * dpp)
    lin = v @ v.T
    kv = beta[0] * lin * ev
    lv, gv, gwv = _gp_term(kv + beta[3] * np.eye(len(cur)), ydot, wv)
    m1 = gv * (beta[0] * ev)
    m2 = gv * kv
    d_v = 2.0 * (m1 @ v) - 2.0 * beta[1] * (m2.sum(1)[:, None] * v - m2 @ v)
    d_p = -2.0 * beta[2] * (m2.sum(1)[:, None] * p - m2 @ p)
    np.add.at(gx, cur, d_v + d_p)
    np.add.at(gx, prev, -d_v)
    gb = np.array([m2.sum(), -0.5 * (m2 * dvv).sum() * beta[1],
                   -0.5 * (m2 * dpp).sum() * beta[2], np.trace(gv) * beta[3]])

    # priors ln p(alpha) = -sum ln alpha_i (eq. 6): d/d ln alpha_i = -1
    value = ly + lv - la.sum() - lb.sum() - 0.5 * x_prior * (x * x).sum()
    gx -= x_prior * x
    grad = np.concatenate([gx.ravel(), ga - 1.0, gb - 1.0, gw, gwv])
    return -value, -grad


@dataclass
class GPLVM:
    """A learned motion model Gamma = {X, Y, alpha, beta, W} (sec. 6.2) ready for prediction.

    Attributes
    ----------
    x : ndarray, shape (N, q), latent points.
    y_mean : ndarray, shape (d_y,), bias of eq. 7; ``y_alpha`` (N, d_y) = K_Y^-1 (Y - bias).
    alpha : ndarray, shape (3,); w : (d_y,) pose scales.
    cur, prev : ndarray, shape (M,), int: velocity samples' frames.
    v_mean : (d_v,); ``v_alpha`` (M, d_v) = K_V^-1 (Ydot - mean); beta (4,); wv (d_v,).
    objective : final value of eq. 6 (up to a constant).
    """

    x: np.ndarray
    y_mean: np.ndarray
    y_alpha: np.ndarray
    alpha: np.ndarray
    w: np.ndarray
    cur: np.ndarray
    prev: np.ndarray
    v_mean: np.ndarray
    v_alpha: np.ndarray
    beta: np.ndarray
    wv: np.ndarray
    objective: float = np.nan

    def pose(self, x: np.ndarray) -> np.ndarray:
        """Eq. 7: GP mean pose of latent points x (..., q) -> (..., d_y)."""
        x = np.asarray(x, dtype=np.float64)
        flat = x.reshape(-1, x.shape[-1])
        out = rbf_kernel(flat, self.x, self.alpha) @ self.y_alpha + self.y_mean
        return out.reshape(x.shape[:-1] + (-1,))

    def velocity(self, x: np.ndarray, x_prev: np.ndarray) -> np.ndarray:
        """Velocity GP mean at ``[x, x - x_prev]`` (..., q) -> (..., d_v)."""
        x = np.asarray(x, dtype=np.float64)
        flat, fprev = x.reshape(-1, x.shape[-1]), np.asarray(x_prev).reshape(-1, x.shape[-1])
        p, v = self.x[self.cur], self.x[self.cur] - self.x[self.prev]
        k = velocity_kernel(flat, flat - fprev, p, v, self.beta)
        return (k @ self.v_alpha + self.v_mean).reshape(x.shape[:-1] + (-1,))

    def project(self, y: np.ndarray, maxiter: int = 100, chunk: int = 4000) -> np.ndarray:
        """Latent points of poses y (B, d_y): argmin_x |W (y - pose(x))|^2, started at the
        latent point of the nearest training pose (back-projection, Lawrence 2005 sec. 6)."""
        y = np.asarray(y, dtype=np.float64)
        ytrain = self.pose(self.x)
        out = np.empty((len(y), self.x.shape[1]))
        for s in range(0, len(y), chunk):
            yb = y[s:s + chunk]
            near = np.argmin(sqdist(yb * self.w, ytrain * self.w), axis=1)
            x0 = self.x[near]
            res = minimize(self._project_loss, x0.ravel(), args=(yb,), jac=True,
                           method="L-BFGS-B", options={"maxiter": maxiter})
            out[s:s + chunk] = res.x.reshape(x0.shape)
        return out

    def _project_loss(self, theta: np.ndarray, y: np.ndarray) -> tuple[float, np.ndarray]:
        x = theta.reshape(len(y), -1)
        k = rbf_kernel(x, self.x, self.alpha)                      # (B, N)
        r = (k @ self.y_alpha + self.y_mean - y) * self.w**2      # (B, d)
        loss = float(((k @ self.y_alpha + self.y_mean - y) ** 2 * self.w**2).sum())
        gk = 2.0 * (r @ self.y_alpha.T) * k                         # dF/dk * k
        gx = -self.alpha[1] * (gk.sum(1)[:, None] * x - gk @ self.x)
        return loss, gx.ravel()


def init_params(y: np.ndarray, ydot: np.ndarray, cur: np.ndarray, prev: np.ndarray,
                q: int) -> np.ndarray:
    """Starting parameter vector for :func:`neg_log_posterior` (see the module docstring).

    y : (N, d_y) centred poses; ydot : (M, d_v) centred velocities.
    """
    w = 1.0 / np.maximum(y.std(0), 1e-6)
    wv = 1.0 / np.maximum(ydot.std(0), 1e-6)
    ys = y * w
    vt = np.linalg.svd(ys - ys.mean(0), full_matrices=False)[2]
    x = (ys - ys.mean(0)) @ vt[:q].T
    x = x / max(x[:, 0].std(), 1e-9)
    if x.shape[1] < q:  # fewer frames than latent dimensions
        x = np.pad(x, ((0, 0), (0, q - x.shape[1])))
    xd = x[cur] - x[prev]
    b2 = 1.0 / max(float((xd ** 2).sum(1).mean()), 1e-9)
    return np.concatenate([x.ravel(), np.log([1.0, 1.0, 1e-2]),
                           np.log([1.0, b2, 1.0, 1e-2]), np.log(w), np.log(wv)])


def fit_gplvm(y: np.ndarray, ydot: np.ndarray, cur: np.ndarray, prev: np.ndarray, q: int = 5,
              maxiter: int = 300, x_prior: float = 1.0) -> GPLVM:
    """Learn X, alpha, beta, W, W_V by maximizing eq. 6 with L-BFGS-B (sec. 5.3).

    Parameters
    ----------
    y : ndarray, shape (N, d_y), pose vectors of the training frames (not centred).
    ydot : ndarray, shape (M, d_v), velocity vectors of the pairs ``(prev[m], cur[m])``.
    cur, prev : ndarray, shape (M,), int: indices into y of each velocity sample's frame and
        the frame before it.
    q : latent dimension (5 in sec. 7).
    maxiter : L-BFGS iterations.
    x_prior : see :func:`neg_log_posterior`.
    """
    y, ydot = np.asarray(y, dtype=np.float64), np.asarray(ydot, dtype=np.float64)
    cur, prev = np.asarray(cur, dtype=np.int64), np.asarray(prev, dtype=np.int64)
    if len(y) < 2 or len(cur) < 2:
        raise ValueError(f"fit_gplvm: need at least 2 frames and 2 velocity samples, got "
                         f"{len(y)} and {len(cur)}")
    y_mean, v_mean = y.mean(0), ydot.mean(0)
    yc, vc = y - y_mean, ydot - v_mean
    n, dy, dv = len(y), y.shape[1], ydot.shape[1]
    theta0 = init_params(yc, vc, cur, prev, q)
    bounds = ([(None, None)] * (n * q) + list(BOUNDS_ALPHA) + list(BOUNDS_BETA)
              + [(None, None)] * (dy + dv))
    theta0 = np.clip(theta0, [b[0] if b[0] is not None else -np.inf for b in bounds],
                     [b[1] if b[1] is not None else np.inf for b in bounds])
    res = minimize(neg_log_posterior, theta0, args=(yc, vc, cur, prev, q, x_prior), jac=True,
                   method="L-BFGS-B", bounds=bounds, options={"maxiter": maxiter})
    x, la, lb, lw, lwv = _unpack(res.x, n, q, dy, dv)
    alpha, beta, w, wv = np.exp(la), np.exp(lb), np.exp(lw), np.exp(lwv)
    ky = rbf_kernel(x, x, alpha) + (alpha[2] + JITTER) * np.eye(n)
    p, v = x[cur], x[cur] - x[prev]
    kv = velocity_kernel(p, v, p, v, beta) + (beta[3] + JITTER) * np.eye(len(cur))
    return GPLVM(x=x, y_mean=y_mean, y_alpha=cho_solve(cho_factor(ky, lower=True), yc),
                 alpha=alpha, w=w, cur=cur, prev=prev, v_mean=v_mean,
                 v_alpha=cho_solve(cho_factor(kv, lower=True), vc), beta=beta, wv=wv,
                 objective=-float(res.fun))
