"""Bring an irregularly sampled recording onto a uniform time line at a model's rate."""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from imuloco.core.recording import Recording
from imuloco.ops.filters import gaussian_smooth, resample_linear
from imuloco.ops.rotations import slerp

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Gap:
    """A stretch without samples longer than the allowed gap, in seconds of the recording."""

    start: float
    stop: float


def find_gaps(times: np.ndarray, max_gap: float) -> list[Gap]:
    """Intervals between consecutive samples longer than ``max_gap`` seconds."""
    d = np.diff(times)
    return [Gap(float(times[i]), float(times[i + 1])) for i in np.flatnonzero(d > max_gap)]


def resample(rec: Recording, rate: float, sigma_s: float = 0.0, max_gap: float = 0.1,
             new_times: np.ndarray | None = None) -> tuple[Recording, list[Gap]]:
    """Resample to ``rate`` Hz by linear interpolation, as the 2014 paper does (sec. 6.1).

    When the target rate is below the source rate the signal is first smoothed with a Gaussian
    of sigma = half a target period (anti-aliasing); ``sigma_s`` adds further smoothing.
    Gaps longer than ``max_gap`` seconds are bridged by the interpolation but returned (and
    logged), never silently.

    ``new_times`` (seconds) overrides the uniform grid that starts at the first sample, e.g.
    to get exactly one sample per motion frame; values past the ends are held.

    Returns
    -------
    The resampled recording and the list of gaps.
    """
    times = rec.times
    gaps = find_gaps(times, max_gap)
    for g in gaps:
        log.warning("recording has no samples from %.3f s to %.3f s (%.3f s gap)",
                    g.start, g.stop, g.stop - g.start)
    src_rate = rec.rate
    dense_t = np.arange(times[0], times[-1] + 1e-9, 1.0 / src_rate)
    chans = resample_linear(times, rec.channels(), dense_t)
    sigma = np.hypot(0.5 / rate if rate < src_rate else 0.0, sigma_s) * src_rate
    chans = gaussian_smooth(chans, sigma)
    new_t = (np.arange(times[0], times[-1] + 1e-9, 1.0 / rate) if new_times is None
             else np.asarray(new_times, dtype=np.float64))
    chans = resample_linear(dense_t, chans, new_t).reshape(len(new_t), -1, 6)
    ori = (None if rec.orientation is None
           else slerp(rec.orientation, times, np.clip(new_t, times[0], times[-1])))
    out = Recording(new_t, chans[..., :3], chans[..., 3:], list(rec.placements), ori)
    return out, gaps
