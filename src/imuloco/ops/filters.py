"""Resampling and smoothing of time series (axis 0 is time)."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d


def gaussian_smooth(x: np.ndarray, sigma: float, axis: int = 0) -> np.ndarray:
    """1-D Gaussian smoothing along ``axis`` (sigma in samples; 0 returns a copy), edges
    handled by reflection. The 2014 paper smooths its phone signals this way (sec. 6.1)."""
    x = np.asarray(x, dtype=np.float64)
    return gaussian_filter1d(x, sigma, axis=axis, mode="nearest") if sigma > 0 else x.copy()


def resample_linear(times: np.ndarray, values: np.ndarray, new_times: np.ndarray) -> np.ndarray:
    """Linear interpolation of ``values`` (T, ...) sampled at increasing ``times`` (T,) onto
    ``new_times`` (N,); outside the range the end values are held."""
    values = np.asarray(values, dtype=np.float64)
    flat = values.reshape(len(times), -1)
    out = np.stack([np.interp(new_times, times, flat[:, k]) for k in range(flat.shape[1])], -1)
    return out.reshape((len(new_times),) + values.shape[1:])
