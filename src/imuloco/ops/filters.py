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


def resample_uniform(times: np.ndarray, values: np.ndarray, rate: float) -> np.ndarray:
    """``values`` (T, ...) sampled at increasing ``times`` (T,) resampled linearly onto the grid
    ``times[0] + arange(n) / rate`` (Hz), as far as ``times[-1]``: at the mean rate
    ``(T - 1) / (times[-1] - times[0])``, T samples."""
    n = _grid_samples(float(times[-1] - times[0]), rate)
    return resample_linear(times, values, times[0] + np.arange(n) / rate)


def _grid_samples(span: float, rate: float) -> int:
    """Samples of a grid at ``rate`` over ``span`` seconds, both ends included: ``span * rate``
    rounded down, unless a billionth (of it, or of a sample when under one) short of a whole
    number, as the mean rate times the span falls short by a rounding error above 2**24 samples."""
    k = span * rate
    return int(np.floor(k + 1e-9 * max(1.0, k))) + 1
