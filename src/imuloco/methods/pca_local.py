"""The PCA local-model baseline of Tautges et al. 2008 sec. 5.2, after Chai and Hodgins 2005.

Frame by frame, the pose minimizes three terms (sec. 5.2, items 1-3):

1. a pose prior: a Gaussian in the local PCA space of the ``k`` database poses nearest to the
   previous reconstructed pose (Chai and Hodgins' local linear model);
2. smoothness: the pose's second difference with the two previous poses;
3. control: each sensor's position against a control position obtained by integrating the
   measured acceleration over one frame from the previous reconstructed poses,
   ``c_t = 2 p_{t-1} - p_{t-2} + a_t dt^2`` (sec. 5.2, last paragraph).

Choices where the papers leave room (noted in the docstrings too):

- Poses are the pose vectors of :mod:`imuloco.methods.pose` (6-D joint rotations, root height,
  root velocity and yaw rate in the heading frame), so the root path is part of the pose.
- The measured specific force is turned into a world acceleration with the sensor's
  orientation in the previous reconstructed pose (the sensors have no magnetometer, and the
  reconstruction's own frame is the one its positions live in): ``a_t = R_{t-1} f_t + g``.
- The first pose is the database pose whose signals are nearest to the first sample.
- The database is subsampled every ``stride`` frames to bound the model file and the search.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from scipy.optimize import leastsq

from imuloco.core.motion import Motion
from imuloco.methods import pose
from imuloco.methods.base import Method
from imuloco.methods.params import Constraint
from imuloco.methods.training import TrainingSet
from imuloco.ops.rotations import from_6d, to_matrix
from imuloco.sensors.placement import anatomical_frame, get_placement
from imuloco.sensors.simulate import GRAVITY


class _Rows:
    """Exact k nearest rows of ``x`` (N, D) to a query (D,), Euclidean.

    A full query is one matrix-vector product (``|x|^2 - 2 x q``) and a partial sort. The
    queries of a reconstruction follow a path (each is the previous frame's pose), so a full
    query also keeps the ``reach`` rows nearest to its point ``a`` and the distance ``R`` from
    ``a`` to the nearest row left out. Every row left out is then at least ``R - |q - a|`` from
    a later query ``q`` (triangle inequality): when the k-th nearest kept row is closer than
    that, the kept rows' answer is the exact one, found among ``reach`` rows instead of N;
    otherwise the query is a full one. The answer never depends on which queries came before
    (up to ties).

    Hand-written because no library index reuses a previous query's neighbourhood, and the
    library trees do not prune here: on the 60,344 scaled poses (130-D, 47 principal axes for
    95 % of the variance) of bandai-namco-2's ``random-clips`` training set, one thread, a
    50-neighbour query took 20.5 ms with scikit-learn's KDTree or BallTree (leaf size 10 or
    40) against 8.3 ms for the full product; 86-91 % of a reconstruction's queries are
    answered from the kept rows with ``reach`` 500-1000."""

    def __init__(self, x: np.ndarray, reach: int = 1000) -> None:
        self.x = np.asarray(x, dtype=np.float64)
        self.norms = np.einsum("ij,ij->i", self.x, self.x)
        self.reach = reach
        # the last full query's kept rows: indices, rows, their squared norms, the query's
        # point and R; one tuple, replaced whole, so that concurrent reconstructions with one
        # model each read a consistent one
        self._kept: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float] | None = None

    def nearest(self, q: np.ndarray, k: int) -> np.ndarray:
        """Indices (min(k, N),) of the rows nearest to q (D,), ascending (exact up to ties)."""
        n = len(self.x)
        if k >= n:
            return np.arange(n)
        kept = self._kept
        if kept is not None and k < len(kept[0]):
            idx, rows, norms, anchor, radius = kept
            d2 = norms - 2.0 * (rows @ q)  # squared distances less |q|^2, as below
            part = np.argpartition(d2, k - 1)[:k]
            if np.sqrt(max(d2[part].max() + q @ q, 0.0)) < radius - np.linalg.norm(q - anchor):
                return np.sort(idx[part])
        d2 = self.norms - 2.0 * (self.x @ q)
        m = min(max(self.reach, k), n - 1)
        near = np.argpartition(d2, m)[: m + 1]
        near = near[np.argsort(d2[near])]
        # R: the nearest row left out, less a margin for the expansion's rounding
        radius = np.sqrt(max(d2[near[m]] + q @ q, 0.0)) * (1 - 1e-9) - 1e-9
        idx = near[:m]
        self._kept = (idx, self.x[idx], self.norms[idx], np.array(q, dtype=np.float64), radius)
        return np.sort(idx[:k])


class PCALocal(Method):
    """Local PCA pose prior with acceleration control (Tautges et al. 2008 sec. 5.2).

    Parameters
    ----------
    k : nearest database poses per frame (Chai and Hodgins 2005 sec. 5; not given in the 2008
        paper).
    energy : fraction of the neighbours' variance the local PCA keeps.
    sigma_control : tolerance of the control term, metres.
    sigma_smooth : tolerance of the smoothness term, pose-vector units per frame^2.
    max_nfev : solver evaluations per frame.
    stride : keep every ``stride``-th training frame.
    """

    summary = "local PCA pose prior + acceleration control, per frame (Chai & Hodgins 2005)"
    # k at most 1000 (50 by default): a neighbourhood that large is no longer local, and each
    # frame's PCA costs O(k); k=1e9 took every training frame for each (74 s on 4 sample clips,
    # not 0.2)
    param_constraints: ClassVar[dict[str, Constraint]] = {
        "k": "[1, 1000]", "energy": "(0, 1]", "sigma_control": "(0, inf)",
        "sigma_smooth": "(0, inf)", "max_nfev": "[1, inf)", "stride": "[1, inf)"}

    def __init__(self, k: int = 50, energy: float = 0.95, sigma_control: float = 0.01,
                 sigma_smooth: float = 0.05, max_nfev: int = 10, stride: int = 2) -> None:
        self.k = k
        self.energy = energy
        self.sigma_control = sigma_control
        self.sigma_smooth = sigma_smooth
        self.max_nfev = max_nfev
        self.stride = stride

    def learn(self, data: TrainingSet, progress: bool = False) -> None:
        vec = [pose.encode(e.motion)[:: self.stride] for e in data.examples]
        sig = [e.signals[:: self.stride] for e in data.examples]
        self.poses_ = np.concatenate(vec).astype(np.float32)
        self.signals_ = np.concatenate(sig).astype(np.float32)
        self.scale_ = self.poses_.std(axis=0) + 1e-6
        self.signal_scale_ = self.signals_.std(axis=0) + 1e-6
        self._nn = None

    # ---- pieces -----------------------------------------------------------------------------
    def _index(self) -> tuple[_Rows, _Rows]:
        """Nearest-neighbour search over the scaled database poses and signals."""
        if getattr(self, "_nn", None) is None:
            self._nn = (_Rows(self.poses_ / self.scale_),
                        _Rows(self.signals_ / self.signal_scale_))
            # database poses settle the sensors' twist, as sensor_trajectory does with a clip
            j = self.skeleton_.num_joints
            some = self.poses_[:: max(1, len(self.poses_) // 200), : 6 * j].astype(np.float64)
            poses = from_6d(some.reshape(len(some), j, 6))
            self._anat = [anatomical_frame(self.skeleton_, get_placement(p), poses)
                          for p in self.placements_]
            # the joints on the chains from the root to the sensors' joints, parents first
            parents, chain = self.skeleton_.parents, set()
            for a in self._anat:
                k = a[0]
                while k >= 0 and k not in chain:
                    chain.add(k)
                    k = int(parents[k])
            self._chain = sorted(chain)  # parents[k] < k: parents first
            at = {k: i for i, k in enumerate(self._chain)}
            self._cols = np.concatenate([np.arange(6 * k, 6 * k + 6) for k in self._chain])
            self._links = [(at[int(parents[k])], self.skeleton_.offsets[k])
                           for k in self._chain[1:]]
            self._ends = [(at[k], off, to_matrix(r)) for k, off, r in self._anat]
        return self._nn

    def _local_model(self, query: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Mean (D,), components (d, D) and standard deviations (d,) of the neighbours.

        The principal axes come from the eigenvectors of the neighbours' (k, k) Gram matrix
        (``x x^T`` has the squared singular values of ``x`` and its left singular vectors):
        the same axes as an SVD of the (k, D) neighbours, for a k by k problem."""
        x = self.poses_[self._index()[0].nearest(query / self.scale_, self.k)].astype(np.float64)
        mu = x.mean(axis=0)
        x -= mu
        ev, u = np.linalg.eigh(x @ x.T)  # ascending
        ev, u = np.maximum(ev[::-1], 0.0), u[:, ::-1]
        var = ev / max(len(x) - 1, 1)
        d = int(np.searchsorted(np.cumsum(var) / max(var.sum(), 1e-12), self.energy) + 1)
        d = min(d, len(var), int(np.sum(ev > ev[0] * 1e-12)))
        s = np.sqrt(ev[:d])
        return mu, (u[:, :d].T @ x) / s[:, None], np.sqrt(var[:d]) + 1e-6

    def _kinematics(self, vec: np.ndarray, root: np.ndarray, theta: float
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """One frame of :func:`imuloco.methods.pose.decode` for many candidate vectors vec
        (C, D) after a frame at ``root`` (3,) and heading ``theta``, followed by
        :func:`imuloco.sensors.simulate.attached_trajectories`: sensor positions (C, S, 3),
        sensor-to-world rotation matrices (C, S, 3, 3), root (C, 3) and heading (C,). The
        solver's inner loop, so only the joints on the sensors' chains, in rotation matrices
        (Gram-Schmidt of the 6-D rotations, as :func:`imuloco.ops.rotations.from_6d`)."""
        j, c = self.skeleton_.num_joints, len(vec)
        six = vec[:, self._cols].reshape(c, -1, 2, 3)  # (C, K, 2, 3) on the chains
        local = np.empty(six.shape[:2] + (3, 3))  # (C, K, 3, 3), columns a, b, a x b
        a = local[..., 0] = six[:, :, 0] / np.sqrt(
            np.einsum("ckx,ckx->ck", six[:, :, 0], six[:, :, 0]))[..., None]
        b = six[:, :, 1] - np.einsum("ckx,ckx->ck", a, six[:, :, 1])[..., None] * a
        b = local[..., 1] = b / np.sqrt(np.einsum("ckx,ckx->ck", b, b))[..., None]
        for i, (u, v) in enumerate(((1, 2), (2, 0), (0, 1))):  # np.cross costs more here
            local[..., i, 2] = a[..., u] * b[..., v] - a[..., v] * b[..., u]
        th = theta + vec[:, 6 * j + 3] / self.fps_
        cos, sin = np.cos(th), np.sin(th)
        vx, vz = vec[:, 6 * j + 1] / self.fps_, vec[:, 6 * j + 2] / self.fps_
        origin = np.empty((c, 3))
        origin[:, 0], origin[:, 1] = root[0] + cos * vx + sin * vz, vec[:, 6 * j]
        origin[:, 2] = root[2] - sin * vx + cos * vz
        yaw = np.zeros((c, 3, 3))
        yaw[:, 0, 0], yaw[:, 0, 2], yaw[:, 1, 1], yaw[:, 2, 0], yaw[:, 2, 2] = cos, sin, 1, -sin, cos
        glob, pos = [yaw @ local[:, 0]], [origin]
        for i, (p, off) in enumerate(self._links, start=1):  # parents first
            pos.append(pos[p] + glob[p] @ off)
            glob.append(glob[p] @ local[:, i])
        ps, ori = np.empty((c, len(self._ends), 3)), np.empty((c, len(self._ends), 3, 3))
        for s, (i, off, rot) in enumerate(self._ends):
            ps[:, s], ori[:, s] = pos[i] + glob[i] @ off, glob[i] @ rot
        return ps, ori, origin, th

    def _solve_frame(self, q1: np.ndarray, q2: np.ndarray, control: np.ndarray,
                     root_prev: np.ndarray, theta: float, h: float = 1e-4
                     ) -> tuple[np.ndarray, tuple[np.ndarray, ...]]:
        """The pose vector (D,) minimizing prior + smoothness + control (sec. 5.2) after the
        poses q1 (t-1) and q2 (t-2), and its :meth:`_kinematics` (one candidate);
        control : (S, 3) sensor positions."""
        mu, comp, sd = self._local_model(q1)
        basis = sd[:, None] * comp                       # (d, D): v = mu + w @ basis
        target = 2 * q1 - q2 - mu                        # smoothness: v - 2 q1 + q2 = 0
        # the prior and smoothness terms are linear in w: their Jacobian is fixed
        linear = np.vstack([np.eye(len(sd)), basis.T / self.sigma_smooth])
        seen: dict[bytes, tuple] = {}

        def control_term(w: np.ndarray) -> tuple:
            # the control residuals at w and their forward differences, from one batch of
            # candidate poses (one kinematics call): the solver asks for the Jacobian at the
            # points it accepts, so each is computed with the residuals it follows
            key = w.tobytes()
            if key not in seen:
                kin = self._kinematics(mu + np.vstack([w, w + h * np.eye(len(w))]) @ basis,
                                       root_prev, theta)
                rr = (kin[0] - control).reshape(len(w) + 1, -1) / self.sigma_control
                seen[key] = (rr[0], ((rr[1:] - rr[0]) / h).T, tuple(k[:1] for k in kin))
            return seen[key]

        def residuals(w: np.ndarray) -> np.ndarray:
            return np.concatenate([
                w,                                       # prior: N(0, sd^2)
                (w @ basis - target) / self.sigma_smooth,  # smoothness
                control_term(w)[0],                      # control
            ])

        def jac(w: np.ndarray) -> np.ndarray:
            return np.vstack([linear, control_term(w)[1]])

        w0 = ((q1 - mu) @ comp.T) / sd
        # MINPACK's Levenberg-Marquardt (lmder) through leastsq: least_squares(method="lm")
        # makes the same call and then one more Jacobian for its report, unused here;
        # full_output only keeps leastsq from warning when max_nfev ends the search
        w = leastsq(residuals, w0, Dfun=jac, full_output=True, ftol=1e-8, xtol=1e-8,
                    gtol=1e-8, maxfev=self.max_nfev)[0]
        return mu + w @ basis, control_term(w)[2]

    # ---- reconstruction ---------------------------------------------------------------------
    def reconstruct_signals(self, signals: np.ndarray) -> Motion:
        signals = np.asarray(signals, dtype=np.float64)
        t = len(signals)
        if t < 1:
            raise ValueError("pca-local: no signals")
        first = self._index()[1].nearest(signals[0] / self.signal_scale_, 1)
        vecs = np.empty((t, self.poses_.shape[1]))
        vecs[0] = self.poses_[first[0]]
        pos, ori, root, th = self._kinematics(vecs[:1], np.zeros(3), 0.0)
        theta = float(th[0])
        p1, p2, r1 = pos[0], pos[0], ori[0]
        root_prev = root[0]
        facc = signals.reshape(t, -1, 6)[:, :, :3]
        dt = 1.0 / self.fps_
        for f in range(1, t):
            q1 = vecs[f - 1]
            q2 = vecs[f - 2] if f >= 2 else q1
            acc = (r1 @ facc[f][:, :, None])[..., 0] + GRAVITY  # world acceleration, (S, 3)
            control = 2 * p1 - p2 + acc * dt * dt
            vecs[f], (pos, ori, root, th) = self._solve_frame(q1, q2, control, root_prev, theta)
            theta, root_prev = float(th[0]), root[0]
            p2, p1, r1 = p1, pos[0], ori[0]
        return pose.decode(vecs, self.skeleton_, self.fps_, start=np.zeros(3))

    # ---- persistence ------------------------------------------------------------------------
    def get_state(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        return {"poses": self.poses_, "signals": self.signals_, "scale": self.scale_,
                "signal_scale": self.signal_scale_}, {}

    def set_state(self, arrays: dict[str, np.ndarray], values: dict[str, Any]) -> None:
        self.poses_, self.signals_ = arrays["poses"], arrays["signals"]
        self.scale_, self.signal_scale_ = arrays["scale"], arrays["signal_scale"]
        self._nn = None
