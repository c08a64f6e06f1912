"""Shared input features: windows of sensor samples, standardization, and the online
counterparts that give the same rows one sample at a time.

A causal window at frame t holds samples ``t - size + 1 .. t`` (oldest first); frames before
the first sample repeat the first sample (edge padding), so an offline window row equals the
row :class:`WindowBuffer` builds online after ``t + 1`` steps.
"""

from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from imuloco.core.motion import Motion
from imuloco.core.skeleton import Skeleton
from imuloco.ops.rotations import about_y, from_6d, qmul, qrot


def windows(signals: np.ndarray, size: int, causal: bool = True) -> np.ndarray:
    """Stack each frame's window of samples into one row.

    Parameters
    ----------
    signals : ndarray, shape (T, C)
    size : samples per window (>= 1).
    causal : windows end at the current frame (online-safe); otherwise centred
        (``size // 2`` samples before, ``(size - 1) // 2`` after).

    Returns
    -------
    ndarray, shape (T, size * C): the window's samples oldest first, each sample's C channels
    contiguous. Edges repeat the first/last sample.
    """
    signals = np.asarray(signals, dtype=np.float64)
    if signals.ndim != 2:
        raise ValueError(f"windows: expected signals (T, C), got shape {signals.shape}")
    if size < 1:
        raise ValueError(f"windows: size must be >= 1, got {size}")
    t, c = signals.shape
    before = size - 1 if causal else size // 2
    padded = np.pad(signals, ((before, size - 1 - before), (0, 0)), mode="edge")
    # (T, C, size) -> (T, size, C)
    view = sliding_window_view(padded, size, axis=0)[:t]
    return np.ascontiguousarray(view.transpose(0, 2, 1)).reshape(t, size * c)


class WindowBuffer:
    """Online causal windows: ``push(sample (C,)) -> row (size * C,)`` equal to
    ``windows(all_samples_so_far, size)[-1]``."""

    def __init__(self, size: int) -> None:
        self.size = size
        self.buf: np.ndarray | None = None

    def push(self, sample: np.ndarray) -> np.ndarray:
        sample = np.asarray(sample, dtype=np.float64)
        if self.buf is None:
            self.buf = np.tile(sample, (self.size, 1))
        else:
            self.buf = np.roll(self.buf, -1, axis=0)
            self.buf[-1] = sample
        return self.buf.reshape(-1).copy()


def fit_standardizer(x: np.ndarray, eps: float = 1e-8) -> tuple[np.ndarray, np.ndarray]:
    """Column means and scales (std, 1 where a column is constant) of x (N, D)."""
    x = np.asarray(x, dtype=np.float64)
    mean, std = x.mean(axis=0), x.std(axis=0)
    return mean, np.where(std > eps, std, 1.0)


def standardize(x: np.ndarray, mean: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """(x - mean) / scale, broadcasting over leading dimensions."""
    return (np.asarray(x, dtype=np.float64) - mean) / scale


class PoseIntegrator:
    """Online :func:`imuloco.methods.pose.decode`: one pose vector (6J+4,) in, one frame's
    local rotations (J, 4) and root (3,) out, integrating heading and horizontal position from
    ``start`` / ``start_heading`` exactly as ``decode`` does (up to quaternion sign)."""

    def __init__(self, skeleton: Skeleton, fps: float, start: np.ndarray | None = None,
                 start_heading: float = 0.0) -> None:
        self.j, self.fps = skeleton.num_joints, fps
        self.theta = start_heading
        self.pos = np.zeros(3) if start is None else np.array(start, dtype=np.float64)
        self.pos[1] = 0.0
        self.first = True

    def step(self, vector: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        j = self.j
        rot = from_6d(np.asarray(vector[: 6 * j]).reshape(j, 6))
        if not self.first:
            self.theta += vector[6 * j + 3] / self.fps
        yaw = about_y(np.asarray(self.theta))
        rot[0] = qmul(yaw, rot[0])
        if not self.first:
            vel = qrot(yaw, np.array([vector[6 * j + 1], 0.0, vector[6 * j + 2]]))
            self.pos[[0, 2]] += vel[[0, 2]] / self.fps
        self.first = False
        root = self.pos.copy()
        root[1] = vector[6 * j]
        return rot, root


def stream_motion(rotations: list[np.ndarray], roots: list[np.ndarray], skeleton: Skeleton,
                  fps: float, name: str = "") -> Motion:
    """Collect per-frame stream outputs into a Motion."""
    return Motion(skeleton, np.stack(rotations), np.stack(roots), fps, name)
