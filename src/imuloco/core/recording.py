"""Recording: body-worn inertial sensor signals on one time line."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imuloco.errors import UnknownNameError


@dataclass(eq=False)
class Recording:
    """Signals of S sensors sampled at common times.

    Attributes
    ----------
    times : ndarray, shape (T,), seconds, increasing (uniform after :meth:`resample`).
    acc : ndarray, shape (T, S, 3), specific force in each sensor's frame, m/s^2 (a resting
        sensor reads +9.81 along its up axis).
    gyro : ndarray, shape (T, S, 3), angular velocity in each sensor's frame, rad/s.
    placements : list of S placement names (see :mod:`imuloco.sensors.placement`).
    orientation : optional ndarray, shape (T, S, 4), sensor-to-world quaternions x, y, z, w as a
        phone's sensor fusion reports them.
    """

    times: np.ndarray
    acc: np.ndarray
    gyro: np.ndarray
    placements: list[str]
    orientation: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.times = np.asarray(self.times, dtype=np.float64)
        self.acc = np.asarray(self.acc, dtype=np.float64)
        self.gyro = np.asarray(self.gyro, dtype=np.float64)
        shape = (len(self.times), len(self.placements), 3)
        if self.acc.shape != shape or self.gyro.shape != shape:
            raise ValueError(f"recording: expected acc and gyro of shape {shape}, got "
                             f"{self.acc.shape} and {self.gyro.shape}")

    @property
    def num_samples(self) -> int:
        return len(self.times)

    @property
    def rate(self) -> float:
        """Mean sampling rate in Hz."""
        return (len(self.times) - 1) / (self.times[-1] - self.times[0])

    def is_uniform(self, tol: float = 1e-6) -> bool:
        d = np.diff(self.times)
        return bool(len(d) == 0 or np.ptp(d) <= tol * max(1.0, d.mean()))

    def select(self, placements: list[str]) -> Recording:
        """The signals of the named placements only, in that order."""
        missing = [p for p in placements if p not in self.placements]
        if missing:
            raise UnknownNameError(f"recording has no sensor at {missing}; it has {self.placements}")
        idx = [self.placements.index(p) for p in placements]
        ori = None if self.orientation is None else self.orientation[:, idx]
        return Recording(self.times, self.acc[:, idx], self.gyro[:, idx], list(placements), ori)

    def channels(self) -> np.ndarray:
        """Signals as one matrix, shape (T, 6 S): per sensor acc x,y,z then gyro x,y,z."""
        return np.concatenate([self.acc, self.gyro], axis=-1).reshape(self.num_samples, -1)
