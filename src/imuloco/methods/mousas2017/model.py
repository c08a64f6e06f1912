"""Frame-state Gaussians over [x, y] and their regression (Mousas 2017 sec. 5.1-5.2, eq. 2-9).

Template learning (sec. 5.2, Figure 7): every frame of every registered segment becomes one
frame state whose mean is that frame, ``mu_i = [mu_i^X, mu_i^Y]`` (eq. 3, 9); the lower level
is not refined across segments, so that each trajectory keeps its own parameters for the
reactive interpolation. The paper leaves open where the covariance ``U_i`` of a single-example
state comes from (eq. 8 only says the upper level is "refined by using the complete number of
motion segments H" of a phase). Chosen here: ``U_i`` is tied across the H segments of a phase
at each registered frame j, estimated from their spread around the phase's mean at j, which is
what registration makes possible, and shrunk towards the phase's pooled covariance and that
towards the global one (weight ``shrinkage`` pseudo-samples), plus a ridge of ``ridge`` times
the global sensor variances on ``U^YY``. One covariance per (phase, registered frame) "group".

From ``U_i`` come the regression of eq. 5-7, ``mu^X(y) = mu^X + U^XY (U^YY)^-1 (y - mu^Y)``
with conditional covariance ``U^XX - U^XY (U^YY)^-1 U^YX`` (its diagonal is kept), and the
emission ``b_i(y) = N(y; mu_i^Y, U_i^YY)``, the y-marginal of eq. 2. The upper level's emission
(eq. 8) is the mean of the H segments' emissions at frame j.

The emission's quadratic form is expanded so that one matrix-vector product over all states
gives every log-likelihood: ``log b_i(y) = m_i . y + c_i - y' P_g y / 2`` with ``P_g`` the
group's precision, ``m_i = P_g mu_i^Y`` and ``c_i`` the constant part.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class FrameStates:
    """Learned arrays of all frame states (N states, G groups, S segments).

    mu_x : (N, dx) float32; mu_y : (N, dy) float32; group : (N,) int, (phase, frame) group;
    states are ordered by phase, then registered frame, then segment.
    reg : (G, dx, dy) regression ``U^XY (U^YY)^-1``; cond_var : (G, dx), diagonal of eq. 7.
    prec : (G, dy, dy) inverse of ``U^YY``; lin : (dy, N) float32 ``P_g mu_i^Y`` (stored
    transposed: the per-frame product ``y @ lin`` then reads memory in order);
    const : (N,) float32 constant part of ``log b_i``.
    group_phase : (G,) int; group_frame : (G,) int; group_count : (G,) segments per group.
    """

    mu_x: np.ndarray
    mu_y: np.ndarray
    group: np.ndarray
    reg: np.ndarray
    cond_var: np.ndarray
    prec: np.ndarray
    lin: np.ndarray
    const: np.ndarray
    group_phase: np.ndarray
    group_frame: np.ndarray
    group_count: np.ndarray

    def __post_init__(self) -> None:
        # phase blocks (first group, first state, H, L); states are frame-major in a block
        # (see :class:`.forward.Topology`), so a group's states are one contiguous run
        self.blocks = []
        st = 0
        for h in np.unique(self.group_phase):
            g = np.flatnonzero(self.group_phase == h)
            big_h, length = int(self.group_count[g[0]]), int(g.size)
            self.blocks.append((int(g[0]), st, big_h, length))
            st += big_h * length
        # the constant as one more row of the product: y_aug = [y, 1] (saves a pass); in lin's
        # precision (float32 in a fitted model)
        self._lin_aug = np.vstack([self.lin, self.const[None, :]]).astype(self.lin.dtype)
        self._y_aug = np.ones(self.lin.shape[0] + 1, dtype=self.lin.dtype)

    def quad(self, y: np.ndarray) -> np.ndarray:
        """``y' P_g y / 2`` of every group, shape (G,) in lin's dtype (float32 in a fitted
        model). y : (dy,) one sensor frame."""
        g, dy = self.prec.shape[:2]
        return ((self.prec.reshape(g * dy, dy) @ y).reshape(g, dy) @ (0.5 * y)).astype(
            self.lin.dtype)

    def linear(self, y: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """``y' lin + const`` of every state, shape (N,) in lin's dtype: log b_i(y) without
        the groups' quadratic term. y : (dy,); out : optional (N,) buffer (returned)."""
        self._y_aug[:-1] = y
        return np.matmul(self._y_aug, self._lin_aug, out=out)

    def log_emission(self, y: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """log b_i(y) for every state, shape (N,) in lin's dtype. y : (dy,) one sensor frame.
        out : optional preallocated (N,) buffer of that dtype (returned)."""
        ll = self.linear(y, out)
        # a group's states are one run (``group`` is sorted), so quad per state is a repeat
        ll -= np.repeat(self.quad(y), self.group_count)
        return ll

    def log_emission_batch(self, y: np.ndarray) -> np.ndarray:
        """log b_i(y_t), shape (T, N). y : (T, dy)."""
        quad = np.einsum("gde,td,te->tg", self.prec, y, y)
        return y @ self.lin.astype(np.float64) + self.const - 0.5 * quad[:, self.group]

    def arrays(self) -> dict[str, np.ndarray]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


def _scatter(xc: np.ndarray, yc: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Scatter blocks summed over axis 0: diag XX (..., dx), XY (..., dx, dy), YY (..., dy, dy).
    xc : (H, ..., dx), yc : (H, ..., dy), centred."""
    return ((xc * xc).sum(0), np.einsum("h...d,h...e->...de", xc, yc),
            np.einsum("h...d,h...e->...de", yc, yc))


def fit_frame_states(
    xs: list[np.ndarray], ys: list[np.ndarray], phases: list[int], shrinkage: float = 10.0,
    ridge: float = 1e-2, sigma_scale: float = 1.0,
) -> FrameStates:
    """Template learning over registered segments.

    Parameters
    ----------
    xs : per phase with segments, ndarray, shape (H, L, dx), registered full-body features.
    ys : per phase, ndarray, shape (H, L, dy), registered sensor features.
    phases : the phase index of each entry of ``xs``.
    shrinkage : pseudo-sample weight of the phase (and global) covariance in each group's.
    ridge : added to U^YY's diagonal, as a fraction of the global sensor variances.
    sigma_scale : the emission's standard deviations (eq. 9's sigma) are ``sigma_scale``
        times those of ``U^YY``; the regression (eq. 6) uses ``U^YY`` itself.
    """
    dx, dy = xs[0].shape[-1], ys[0].shape[-1]
    # frame-major inside each phase block: state = start + j H + s
    all_x = np.concatenate([x.transpose(1, 0, 2).reshape(-1, dx) for x in xs])
    all_y = np.concatenate([y.transpose(1, 0, 2).reshape(-1, dy) for y in ys])
    gxx, gxy, gyy = _scatter(all_x - all_x.mean(0), all_y - all_y.mean(0))
    n_all = max(len(all_x) - 1, 1)
    glob = (gxx / n_all, gxy / n_all, gyy / n_all)
    floor = ridge * np.diag(glob[2]) + 1e-9

    reg, cond, prec, logdet, g_phase, g_frame, g_count = [], [], [], [], [], [], []
    for h, x, y in zip(phases, xs, ys):
        big_h, length = x.shape[:2]
        sxx, sxy, syy = _scatter(x - x.mean(0), y - y.mean(0))  # (L, dx), (L, dx, dy), ...
        dof_j = big_h - 1
        dof_p = dof_j * length
        phase = tuple((s.sum(0) + shrinkage * g) / (dof_p + shrinkage)
                      for s, g in zip((sxx, sxy, syy), glob))
        uxx = (sxx + shrinkage * phase[0]) / (dof_j + shrinkage)
        uxy = (sxy + shrinkage * phase[1]) / (dof_j + shrinkage)
        uyy = (syy + shrinkage * phase[2]) / (dof_j + shrinkage)
        uyy = uyy + np.diag(floor)
        p = np.linalg.inv(uyy)
        a = uxy @ p
        reg.append(a)
        cond.append(np.maximum(uxx - np.einsum("lde,lde->ld", a, uxy), 0.0))
        prec.append(p / sigma_scale**2)
        logdet.append(np.linalg.slogdet(uyy)[1] + 2 * uyy.shape[-1] * np.log(sigma_scale))
        g_phase.append(np.full(length, h))
        g_frame.append(np.arange(length))
        g_count.append(np.full(length, big_h))
    offsets = np.cumsum([0] + [x.shape[1] for x in xs])
    group = np.concatenate([off + np.repeat(np.arange(x.shape[1]), x.shape[0])
                            for off, x in zip(offsets, xs)]).astype(np.intp)
    prec_a, logdet_a = np.concatenate(prec), np.concatenate(logdet)
    mu_y = all_y
    lin = np.einsum("nde,ne->nd", prec_a[group], mu_y)
    const = -0.5 * (lin * mu_y).sum(1) - 0.5 * logdet_a[group] - 0.5 * dy * np.log(2 * np.pi)
    return FrameStates(
        mu_x=all_x.astype(np.float32), mu_y=mu_y.astype(np.float32), group=group,
        reg=np.concatenate(reg), cond_var=np.concatenate(cond), prec=prec_a,
        lin=np.ascontiguousarray(lin.T, dtype=np.float32), const=const.astype(np.float32),
        group_phase=np.concatenate(g_phase), group_frame=np.concatenate(g_frame),
        group_count=np.concatenate(g_count),
    )
