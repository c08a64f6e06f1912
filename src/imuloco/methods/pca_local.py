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

from typing import Any

import numpy as np
from scipy.optimize import least_squares

from imuloco.core.motion import Motion
from imuloco.methods import pose
from imuloco.methods.base import Method
from imuloco.methods.training import TrainingSet
from imuloco.ops.rotations import about_y, from_6d, qmul, qrot
from imuloco.sensors.placement import anatomical_frame, get_placement
from imuloco.sensors.simulate import GRAVITY, attached_trajectories


class _Rows:
    """Exact k nearest rows of ``x`` (N, D) to a query (D,), Euclidean, by brute force:
    ``|x|^2 - 2 x q`` in one matrix-vector product, then a partial sort. Measured on the 74,863
    poses (130-D) of bandai-namco-2, one thread: 9.4 ms a 50-neighbour query, against 17.8 for
    scikit-learn's NearestNeighbors and 24.7 for scipy's KDTree (trees do not prune in 130
    dimensions; scikit-learn's per-call checks add about a millisecond to every query)."""

    def __init__(self, x: np.ndarray) -> None:
        self.x = np.asarray(x, dtype=np.float64)
        self.norms = np.einsum("ij,ij->i", self.x, self.x)

    def nearest(self, q: np.ndarray, k: int) -> np.ndarray:
        """Indices (min(k, N),) of the rows nearest to q (D,), in no particular order."""
        d = self.norms - 2.0 * (self.x @ q)
        k = min(k, len(d))
        return np.argpartition(d, k - 1)[:k] if k < len(d) else np.arange(len(d))


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
            self._chain = sorted(chain)
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

    def _step(self, vec: np.ndarray, root: np.ndarray, theta: float
              ) -> tuple[np.ndarray, np.ndarray, float]:
        """One frame of :func:`imuloco.methods.pose.decode` for many candidate vectors:
        vec (C, D) after a frame at ``root`` (3,) and heading ``theta`` -> local rotations
        (C, J, 4), root (C, 3), heading (C,)."""
        j = self.skeleton_.num_joints
        rot = from_6d(vec[:, : 6 * j].reshape(len(vec), j, 6))
        th = theta + vec[:, 6 * j + 3] / self.fps_
        yaw = about_y(th)
        rot[:, 0] = qmul(yaw, rot[:, 0])
        vel = np.zeros((len(vec), 3))
        vel[:, [0, 2]] = vec[:, 6 * j + 1: 6 * j + 3]
        new_root = root + qrot(yaw, vel) / self.fps_
        new_root[:, 1] = vec[:, 6 * j]
        return rot, new_root, th

    def _sensors(self, rot: np.ndarray, root: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Sensor positions (C, S, 3) and orientations (C, S, 4) of poses."""
        m = Motion(self.skeleton_, rot, root, self.fps_)
        return attached_trajectories(m, self._anat)

    def _sensor_positions(self, vec: np.ndarray, root: np.ndarray, theta: float) -> np.ndarray:
        """Sensor positions (C, S, 3) of the poses :meth:`_step` makes of vec (C, D) after a
        frame at ``root`` (3,) and heading ``theta``: the solver's inner loop, so only the
        joints on the sensors' chains, in rotation matrices (Gram-Schmidt of the 6-D
        rotations, as :func:`imuloco.ops.rotations.from_6d`), without quaternions."""
        sk, j, chain = self.skeleton_, self.skeleton_.num_joints, self._chain
        six = vec[:, : 6 * j].reshape(len(vec), j, 6)[:, chain]
        a = six[..., :3] / np.sqrt(np.sum(six[..., :3] ** 2, axis=-1, keepdims=True))
        b = six[..., 3:] - np.sum(a * six[..., 3:], axis=-1, keepdims=True) * a
        b /= np.sqrt(np.sum(b * b, axis=-1, keepdims=True))
        local = np.empty(six.shape[:-1] + (3, 3))  # (C, K, 3, 3), columns a, b, a x b
        local[..., 0], local[..., 1] = a, b
        for i, (u, v) in enumerate(((1, 2), (2, 0), (0, 1))):  # np.cross costs more here
            local[..., i, 2] = a[..., u] * b[..., v] - a[..., v] * b[..., u]
        th = theta + vec[:, 6 * j + 3] / self.fps_
        c, s = np.cos(th), np.sin(th)
        yaw = np.zeros((len(vec), 3, 3))
        yaw[:, 0, 0], yaw[:, 0, 2], yaw[:, 1, 1], yaw[:, 2, 0], yaw[:, 2, 2] = c, s, 1.0, -s, c
        vel = np.zeros((len(vec), 3))
        vel[:, [0, 2]] = vec[:, 6 * j + 1: 6 * j + 3]
        origin = root + (yaw @ vel[:, :, None])[..., 0] / self.fps_
        origin[:, 1] = vec[:, 6 * j]
        glob: dict[int, np.ndarray] = {}
        pos: dict[int, np.ndarray] = {}
        for i, k in enumerate(chain):
            p = int(sk.parents[k])
            if p < 0:
                glob[k], pos[k] = yaw @ local[:, i], origin
            else:
                glob[k] = glob[p] @ local[:, i]
                pos[k] = pos[p] + glob[p] @ sk.offsets[k]
        return np.stack([pos[k] + glob[k] @ off for k, off, _ in self._anat], axis=1)

    def _solve_frame(self, q1: np.ndarray, q2: np.ndarray, control: np.ndarray,
                     root_prev: np.ndarray, theta: float) -> np.ndarray:
        """The pose vector (D,) minimizing prior + smoothness + control (sec. 5.2) after the
        poses q1 (t-1) and q2 (t-2); control : (S, 3) sensor positions."""
        mu, comp, sd = self._local_model(q1)

        def residuals(w: np.ndarray) -> np.ndarray:
            w = np.atleast_2d(w)
            v = mu + (w * sd) @ comp
            ps = self._sensor_positions(v, root_prev, theta)
            return np.concatenate([
                w,                                                        # prior: N(0, sd^2)
                (v - 2 * q1 + q2) / self.sigma_smooth,                    # smoothness
                (ps - control).reshape(len(w), -1) / self.sigma_control,  # control
            ], axis=1)

        def jac(w: np.ndarray, h: float = 1e-4) -> np.ndarray:
            # forward differences as one batch of candidate poses (one FK)
            rr = residuals(np.vstack([w, w + h * np.eye(len(w))]))
            return ((rr[1:] - rr[0]) / h).T

        w0 = ((q1 - mu) @ comp.T) / sd
        res = least_squares(lambda w: residuals(w)[0], w0, jac=jac, method="trf",
                            max_nfev=self.max_nfev)
        return mu + (res.x * sd) @ comp

    # ---- reconstruction ---------------------------------------------------------------------
    def reconstruct_signals(self, signals: np.ndarray) -> Motion:
        signals = np.asarray(signals, dtype=np.float64)
        t = len(signals)
        if t < 1:
            raise ValueError("pca-local: no signals")
        first = self._index()[1].nearest(signals[0] / self.signal_scale_, 1)
        vecs = np.empty((t, self.poses_.shape[1]))
        vecs[0] = self.poses_[first[0]]
        rot, root, th = self._step(vecs[:1], np.zeros(3), 0.0)
        theta = float(th[0])
        pos, ori = self._sensors(rot, root)
        p1, p2, r1 = pos[0], pos[0], ori[0]
        root_prev = root[0]
        facc = signals.reshape(t, -1, 6)[:, :, :3]
        dt = 1.0 / self.fps_
        for f in range(1, t):
            q1 = vecs[f - 1]
            q2 = vecs[f - 2] if f >= 2 else q1
            acc = qrot(r1, facc[f]) + GRAVITY          # world acceleration, (S, 3)
            control = 2 * p1 - p2 + acc * dt * dt
            vecs[f] = self._solve_frame(q1, q2, control, root_prev, theta)
            rot, root, th = self._step(vecs[f:f + 1], root_prev, theta)
            theta, root_prev = float(th[0]), root[0]
            pos, ori = self._sensors(rot, root)
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
